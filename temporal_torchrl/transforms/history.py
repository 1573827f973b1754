"""The k-step embedding history: s_0 and s_{t-k} next to every s_t (thesis 4.1, 4.3.2), and
optionally the window of the last K embeddings s_{t-K+1} .. s_t (beyond the thesis, section 6.3
proposal: the input of d_sequence)."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import Tensor
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from temporal_torchrl.defaults import K
from temporal_torchrl.rewards.temporal import check_window_length

INITIAL_EMBEDDING_KEY = "initial_embedding"
PREVIOUS_EMBEDDING_KEY = "previous_embedding"
WINDOW_KEY = "embedding_window"


class EmbeddingHistoryTransform(Transform):
    """Writes ``"initial_embedding"`` (s_0) and ``"previous_embedding"`` (s_{t-k}) at every step,
    and with ``window_length`` also ``"embedding_window"`` (s_{t-K+1} .. s_t, ``[K, D]``).

    s_0 is the first embedding of the current episode; s_{t-k} is the embedding k steps back in
    the same episode, clamped to s_0 while t < k (the history never crosses an episode boundary);
    the window likewise holds s_0 in its slots before the episode's start.
    Each batch element keeps a ring of its last max(k, K - 1) + 1 embeddings; a reset fills the
    ring of every reset element with its new s_0, so partial resets of batched envs (the
    ``"_reset"`` mask) restart only those elements. A single cursor serves the whole batch
    because all elements step together. The ring, s_0 and the cursor are buffers, as
    ``CatFrames`` keeps its own: ``state_dict()``, ``.to()`` and :meth:`clone` carry them, so a
    transform saved, moved or cloned mid-episode goes on where it was.

    The transform is stateful and runs only inside an environment: a sampled batch already
    carries the two keys as they were collected, so :meth:`forward` raises.
    Place it after the embedding transform, and on the outer env of a batched env.

    Args:
        k: history offset (>= 1); use the ``k`` of the
            :class:`~temporal_torchrl.rewards.TemporalReward`.
        in_key: the embedding key to track.
        window_length: K (>= 2), or None for no window; use the ``window_length`` of the
            :class:`~temporal_torchrl.rewards.TemporalReward` (None unless its reward reads a
            window).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> history = EmbeddingHistoryTransform(k=2)
        >>> td = history._reset(TensorDict(), TensorDict({"embedding": torch.zeros(3)}))
        >>> for t in range(1, 4):
        ...     step = TensorDict({"embedding": torch.full((3,), float(t))})
        ...     next_td = history._step(TensorDict(), step)
        >>> next_td["previous_embedding"].tolist(), next_td["initial_embedding"].tolist()
        ([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    """

    def __init__(self, k: int = K, in_key: str = "embedding",
                 window_length: int | None = None):
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ValueError(f"k={k!r}; expected an integer >= 1 (the offset of s_(t-k)).")
        check_window_length(window_length, optional=True)
        out_keys = [INITIAL_EMBEDDING_KEY, PREVIOUS_EMBEDDING_KEY]
        super().__init__(in_keys=[in_key],
                         out_keys=out_keys + ([WINDOW_KEY] if window_length else []))
        self.k = k
        self.in_key = in_key
        self.window_length = window_length
        # The ring reaches back far enough for both s_{t-k} and the window's oldest s_{t-K+1}.
        self._size = max(k, (window_length or 1) - 1) + 1
        # Shaped by the first reset: None until then (and absent from state_dict()).
        self._ring: Tensor | None  # [*batch, size, D], slot of s_t at the cursor
        self._initial: Tensor | None  # [*batch, D]
        self.register_buffer("_ring", None)
        self.register_buffer("_initial", None)
        # The ring slot of the newest embedding s_t.
        self.register_buffer("_cursor", torch.zeros((), dtype=torch.int64))

    def _write(self, tensordict: TensorDictBase) -> TensorDictBase:
        # Clones: the ring is updated in place, and the outputs must not change with it.
        cursor = int(self._cursor)
        previous = self._ring[..., (cursor - self.k) % self._size, :]
        tensordict.set(INITIAL_EMBEDDING_KEY, self._initial.clone())
        tensordict.set(PREVIOUS_EMBEDDING_KEY, previous.clone())
        if self.window_length:
            slots = (cursor - torch.arange(self.window_length - 1, -1, -1)) % self._size
            tensordict.set(WINDOW_KEY, self._ring[..., slots.to(self._ring.device), :])
        return tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
               ) -> TensorDictBase:
        embedding = tensordict_reset.get(self.in_key, None)
        if embedding is None:
            raise KeyError(f"EmbeddingHistoryTransform: {self.in_key!r} is missing at reset; put "
                           "the embedding transform before the history transform.")
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        ring_shape = (*embedding.shape[:-1], self._size, embedding.shape[-1])
        if (reset is None or self._ring is None or self._ring.shape != ring_shape
                or self._ring.device != embedding.device):
            self._ring = embedding.unsqueeze(-2).expand(ring_shape).clone()
            self._initial = embedding.clone()
        else:
            # "_reset" is shaped like "done" ([*batch, 1]); one flag per batch element.
            mask = reset.reshape(*embedding.shape[:-1], -1).any(-1)
            self._ring = torch.where(mask[..., None, None], embedding.unsqueeze(-2), self._ring)
            self._initial = torch.where(mask[..., None], embedding, self._initial)
        return self._write(tensordict_reset)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase
              ) -> TensorDictBase:
        if self._ring is None:
            raise RuntimeError("EmbeddingHistoryTransform: step before reset; call env.reset() "
                               "first.")
        cursor = (int(self._cursor) + 1) % self._size
        self._cursor.fill_(cursor)
        self._ring[..., cursor, :] = next_tensordict.get(self.in_key)
        return self._write(next_tensordict)

    def clone(self) -> EmbeddingHistoryTransform:
        # TorchRL's clone shares the buffers' tensors; the ring is written in place.
        copy = super().clone()
        for name, buffer in self._buffers.items():
            setattr(copy, name, None if buffer is None else buffer.clone())
        return copy

    def _load_from_state_dict(self, state_dict: dict, prefix: str, *args, **kwargs) -> None:
        # A transform that has not been reset holds no ring yet: give it one of the saved shape
        # for torch to fill.
        for name in ("_ring", "_initial"):
            saved = state_dict.get(prefix + name)
            if saved is not None and getattr(self, name) is None:
                setattr(self, name, torch.empty_like(saved))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        raise RuntimeError(
            "EmbeddingHistoryTransform is stateful and only runs inside an environment. Sampled "
            "batches already carry 'initial_embedding' and 'previous_embedding' (and "
            "'embedding_window') as collected; relabel them with TemporalRewardTransform alone.")

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        if self.in_key not in observation_spec.keys(True):
            raise KeyError(f"EmbeddingHistoryTransform: no {self.in_key!r} in the observation "
                           "spec; put the embedding transform before the history transform.")
        embedding_spec = observation_spec[self.in_key]
        observation_spec[INITIAL_EMBEDDING_KEY] = embedding_spec.clone()
        observation_spec[PREVIOUS_EMBEDDING_KEY] = embedding_spec.clone()
        if self.window_length:
            shape = embedding_spec.shape
            observation_spec[WINDOW_KEY] = Unbounded(
                shape=(*shape[:-1], self.window_length, shape[-1]), dtype=embedding_spec.dtype,
                device=embedding_spec.device)
        return observation_spec

    def extra_repr(self) -> str:
        window = f", window_length={self.window_length}" if self.window_length else ""
        return f"k={self.k}, in_key={self.in_key!r}{window}"
