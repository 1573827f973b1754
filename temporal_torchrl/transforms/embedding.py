"""Observation -> ``embedding`` with a frozen encoder, in envs and in replay buffers.

The thesis's rewards (ch. 4) are functions of the embedding ``s_t`` of the frame rendered at each
step; :class:`EmbeddingTransform` produces it as the ``"embedding"`` key, at reset and after every
step, so that the history and reward transforms downstream only ever see compact ``[D]`` vectors.
"""

from __future__ import annotations

import contextlib

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey, unravel_key
from torchrl.data.tensor_specs import Composite, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

from temporal_torchrl.encoders.base import Encoder

_AUTOCAST_DTYPES = {
    None: None,
    torch.bfloat16: torch.bfloat16,
    torch.float16: torch.float16,
    "bfloat16": torch.bfloat16,
    "bf16": torch.bfloat16,
    "float16": torch.float16,
    "fp16": torch.float16,
}


class EmbeddingTransform(Transform):
    """Embed ``in_key`` (frames or state vectors) into ``out_key`` (float32 ``[*batch, D]``).

    Env path: runs at reset and at every step; all batch dimensions (a ``SerialEnv`` or
    ``ParallelEnv`` with the transform on the outer env, or a time dimension) are flattened into
    ONE encoder forward. Replay-buffer path (:meth:`forward`): embeds ``in_key`` and
    ``("next", in_key)`` of a batch of transitions, whichever are present, also in one forward.

    The encoder runs under ``torch.inference_mode`` (optionally in autocast) on ``device``; the
    output is copied out of inference mode, back to the input's device, as float32, so that
    losses can use it (inference tensors cannot be saved for backward).

    Args:
        encoder: a frozen :class:`~temporal_torchrl.encoders.Encoder`.
        in_key: the key to embed; default ``encoder.input_key`` (``"pixels"`` or
            ``"observation"``).
        out_key: where the embedding goes (``"embedding"``).
        device: where the encoder runs (e.g. ``"cuda"`` for an env on the CPU); default: where
            the encoder is. The encoder is kept there even when the env moves the transform.
        autocast_dtype: ``torch.bfloat16`` / ``torch.float16`` (or ``"bf16"`` / ``"fp16"``)
            to run the encoder in autocast; ``None`` (default) runs it in float32.
        del_in_key: drop ``in_key`` from the data and the spec after embedding. ``None``
            (default) drops images (``"pixels"``, to keep buffers small) and keeps state
            vectors (the policy still reads ``"observation"``).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from temporal_torchrl.encoders import load_encoder
        >>> transform = EmbeddingTransform(load_encoder("state", dim=8))
        >>> data = TensorDict({"observation": torch.zeros(4, 39),
        ...                    "next": {"observation": torch.ones(4, 39)}}, batch_size=[4])
        >>> data = transform(data)  # as a replay-buffer transform
        >>> data["embedding"].shape, data["next", "embedding"].shape
        (torch.Size([4, 8]), torch.Size([4, 8]))

    In an env (``make_env`` from :mod:`temporal_torchrl.envs`)::

        env = make_env("drawer-open", render=True, image_size=224)  # LIV reads 224 px
        env.append_transform(EmbeddingTransform(load_encoder("liv"), device="cuda",
                                                autocast_dtype=torch.bfloat16))
    """

    def __init__(
        self,
        encoder: Encoder,
        in_key: NestedKey | None = None,
        out_key: NestedKey = "embedding",
        device: str | torch.device | None = None,
        autocast_dtype: torch.dtype | str | None = None,
        del_in_key: bool | None = None,
    ) -> None:
        if not isinstance(encoder, Encoder):
            raise ValueError(
                f"encoder must be a temporal_torchrl Encoder, got {type(encoder).__name__}; "
                "build one with temporal_torchrl.encoders.load_encoder(name)"
            )
        if autocast_dtype not in _AUTOCAST_DTYPES:
            raise ValueError(
                f"autocast_dtype must be None, torch.bfloat16 or torch.float16, got "
                f"{autocast_dtype!r}"
            )
        in_key = unravel_key(in_key if in_key is not None else encoder.input_key)
        super().__init__(in_keys=[in_key], out_keys=[unravel_key(out_key)])
        self.encoder = encoder
        self._device = torch.device(device) if device is not None else None
        if self._device is not None:
            encoder.to(self._device)
        self.autocast_dtype = _AUTOCAST_DTYPES[autocast_dtype]
        self.del_in_key = encoder.input_key == "pixels" if del_in_key is None else del_in_key

    @property
    def in_key(self) -> NestedKey:
        return self.in_keys[0]

    @property
    def out_key(self) -> NestedKey:
        return self.out_keys[0]

    def embed(self, inputs: torch.Tensor) -> torch.Tensor:
        """Inputs ``[*batch, *item]`` -> float32 embeddings ``[*batch, D]``, in one forward."""
        item_ndim = self.encoder.input_ndim
        if inputs.ndim < item_ndim:
            raise ValueError(
                f"{self.in_key!r} has shape {tuple(inputs.shape)}, expected "
                f"[*batch, {'H, W, 3' if item_ndim == 3 else 'obs_dim'}]"
            )
        batch_shape = inputs.shape[: inputs.ndim - item_ndim]
        flat = inputs.reshape(-1, *inputs.shape[inputs.ndim - item_ndim:])
        if flat.shape[0] == 0:
            return torch.zeros(*batch_shape, self.encoder.dim, device=inputs.device)
        if self._device is not None and self.encoder.device != self._device:
            # TransformedEnv moves its transforms to the env's device; the encoder stays pinned.
            self.encoder.to(self._device)
        device = self.encoder.device
        autocast = (torch.autocast(device.type, dtype=self.autocast_dtype)
                    if self.autocast_dtype is not None else contextlib.nullcontext())
        with torch.inference_mode(), autocast:
            embeddings = self.encoder.embed(flat.to(device, non_blocking=True))
        # Copied outside inference mode so reward heads and losses can build graphs on it.
        embeddings = embeddings.to(inputs.device, torch.float32)
        if embeddings.is_inference():
            embeddings = embeddings.clone()
        return embeddings.reshape(*batch_shape, self.encoder.dim)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        inputs = next_tensordict.get(self.in_key, None)
        if inputs is None:
            if self.missing_tolerance:
                return next_tensordict
            raise KeyError(
                f"EmbeddingTransform: {self.in_key!r} not found (keys: "
                f"{sorted(map(str, next_tensordict.keys(True, True)))}); put a transform that "
                "writes it (e.g. RenderTransform for 'pixels') before this one"
            )
        next_tensordict.set(self.out_key, self.embed(inputs))
        if self.del_in_key:
            next_tensordict.exclude(self.in_key, inplace=True)
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
               ) -> TensorDictBase:
        # Transform._reset does not call _call: without this the first embedding is missing.
        return self._call(tensordict_reset)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Replay-buffer path: embed ``in_key`` and ``("next", in_key)``, whichever are present."""
        pairs = [
            (unravel_key(source), unravel_key(target))
            for source, target in ((self.in_key, self.out_key),
                                   (("next", self.in_key), ("next", self.out_key)))
        ]
        present = [(source, target) for source, target in pairs
                   if tensordict.get(source, None) is not None]
        if not present:
            raise KeyError(
                f"EmbeddingTransform: neither {pairs[0][0]!r} nor {pairs[1][0]!r} found in "
                f"the batch (keys: {sorted(map(str, tensordict.keys(True, True)))})"
            )
        inputs = [tensordict.get(source) for source, _ in present]
        if len(inputs) > 1 and inputs[0].shape == inputs[1].shape:
            embeddings = self.embed(torch.stack(inputs)).unbind(0)
        else:
            embeddings = [self.embed(value) for value in inputs]
        for (source, target), embedding in zip(present, embeddings, strict=True):
            tensordict.set(target, embedding)
            if self.del_in_key:
                tensordict.exclude(source, inplace=True)
        return tensordict

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        if not isinstance(observation_spec, Composite) or self.in_key not in observation_spec.keys(
                True, True):
            raise KeyError(
                f"EmbeddingTransform reads {self.in_key!r}, which the env's observation spec "
                "does not have; render frames first (make_env(..., render=True)) or pick "
                "in_key / an encoder whose input the env provides"
            )
        in_spec = observation_spec[self.in_key]
        batch_shape = in_spec.shape[: len(in_spec.shape) - self.encoder.input_ndim]
        observation_spec[self.out_key] = Unbounded(
            shape=torch.Size([*batch_shape, self.encoder.dim]), dtype=torch.float32,
            device=in_spec.device,
        )
        if self.del_in_key:
            del observation_spec[self.in_key]
        return observation_spec

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(encoder={self.encoder.name!r}, in_key={self.in_key!r}, "
                f"out_key={self.out_key!r}, device={self._device}, "
                f"autocast_dtype={self.autocast_dtype}, del_in_key={self.del_in_key})")
