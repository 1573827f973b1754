"""The frozen encoder interface every reward in the package reads its embeddings from.

An :class:`Encoder` maps one kind of input (rendered frames or state vectors, named by
``input_key``) and text prompts into one shared ``dim``-dimensional space. The thesis's rewards
(ch. 4) compare an observation's embedding ``s_t`` with the goal ``g`` and baseline ``b`` prompt
embeddings in that space, so both towers of an encoder must come from the same model.

Encoders are frozen: their parameters never require gradients and they stay in eval mode even
when a parent module is put in training mode (RN50's BatchNorm would otherwise update its running
statistics on every frame it embeds).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import torch
from torch import nn

INPUT_KEYS = ("pixels", "observation")
#: Frames whose shorter side is below this fraction of :attr:`Encoder.frame_size` are refused,
#: below :data:`WARN_FRAME_FRACTION` warned about: the encoder upsamples them into a blur.
MIN_FRAME_FRACTION = 1 / 4
WARN_FRAME_FRACTION = 1 / 2


class Encoder(nn.Module):
    """Base class of the package's frozen encoders.

    Subclasses set ``name``, ``dim`` and ``input_key`` and implement :meth:`_encode_text` and
    either :meth:`embed_images` (``input_key="pixels"``) or :meth:`embed_observations`
    (``input_key="observation"``).

    Attributes:
        name: the registry name (``load_encoder(name)``).
        dim: the embedding size ``D``.
        input_key: the tensordict key the encoder reads: ``"pixels"`` (uint8 ``[H, W, 3]``
            frames) or ``"observation"`` (float ``[39]`` state vectors).
    """

    name: str = "encoder"
    dim: int
    input_key: str = "pixels"

    def __init__(self) -> None:
        super().__init__()
        # Prompts are few per run (goal, baseline) and their embeddings never change while the
        # weights don't, so they are computed once. Kept on the CPU so moving the encoder to
        # another device does not invalidate them.
        self._text_cache: dict[str, torch.Tensor] = {}

    @property
    def input_ndim(self) -> int:
        """Number of trailing dimensions of one input item: 3 for ``[H, W, 3]``, 1 for ``[39]``."""
        return 3 if self.input_key == "pixels" else 1

    @property
    def frame_size(self) -> int | None:
        """Side of the square frames the image tower was trained on and reads (frames of another
        size are resized to it); None for encoders that read no pixels."""
        return None

    def check_frame_size(self, size: int | Sequence[int]) -> None:
        """Refuse (ValueError) or warn about rendered frames of ``size`` (a side, or ``(height,
        width)``) far smaller than :attr:`frame_size`: below :data:`MIN_FRAME_FRACTION` of it
        they are refused, below :data:`WARN_FRAME_FRACTION` warned about.

        >>> from temporal_torchrl.encoders import load_encoder
        >>> load_encoder("metaworld_small").check_frame_size(7)
        Traceback (most recent call last):
        ...
        ValueError: frames of 7x7 px are far smaller than the 64x64 px frames the \
'metaworld_small' encoder was trained on: ...
        """
        expected = self.frame_size
        height, width = (size, size) if isinstance(size, int) else tuple(size)
        side = min(height, width)
        if expected is None or side <= 0 or side >= expected * WARN_FRAME_FRACTION:
            return  # (a side <= 0 is the renderer's to refuse)
        far = side < expected * MIN_FRAME_FRACTION
        message = (
            f"frames of {height}x{width} px are {'far ' if far else ''}smaller than the "
            f"{expected}x{expected} px frames the {self.name!r} encoder was trained on: it "
            f"upsamples them {expected / side:.1f}x, so its embeddings, and every VLM reward "
            f"computed from them, describe a blur. Render at image_size={expected} (in the "
            f"recipe: env.image_size={expected}).")
        if far:
            raise ValueError(message)
        warnings.warn(message, stacklevel=2)

    @property
    def device(self) -> torch.device:
        """The device the encoder's weights live on."""
        for tensor in self.parameters():
            return tensor.device
        for tensor in self.buffers():
            return tensor.device
        return torch.device("cpu")

    def train(self, mode: bool = True) -> Encoder:
        """Keep the encoder in eval mode whatever ``mode`` is: it is a frozen feature extractor."""
        return super().train(False)

    def freeze(self) -> Encoder:
        """Put the encoder in eval mode, with no parameter requiring gradients."""
        self.requires_grad_(False)
        return self.train(False)

    def embed_images(self, frames: torch.Tensor) -> torch.Tensor:
        """Embed uint8 RGB frames ``[N, H, W, 3]`` into float32 ``[N, dim]``."""
        raise NotImplementedError(
            f"the {self.name!r} encoder reads {self.input_key!r}, not images: call "
            f"embed(inputs) with {self.input_key!r} tensors, or pick an image encoder "
            "such as load_encoder('liv')"
        )

    def embed_observations(self, observations: torch.Tensor) -> torch.Tensor:
        """Embed state vectors ``[N, obs_dim]`` into float32 ``[N, dim]``."""
        raise NotImplementedError(
            f"the {self.name!r} encoder reads {self.input_key!r}, not state vectors: call "
            "embed_images(frames) with uint8 [N, H, W, 3] frames, or use load_encoder('state')"
        )

    def embed(self, inputs: torch.Tensor) -> torch.Tensor:
        """Embed a batch of what ``input_key`` names (frames or state vectors) -> ``[N, dim]``."""
        if self.input_key == "pixels":
            return self.embed_images(inputs)
        return self.embed_observations(inputs)

    def embed_text(self, texts: Sequence[str]) -> torch.Tensor:
        """Embed prompts into float32 ``[len(texts), dim]``, computing each prompt only once.

        Args:
            texts: a list of prompts, e.g. ``["open the drawer", "robot arm beside table"]``.
        """
        if isinstance(texts, str) or not all(isinstance(text, str) for text in texts):
            raise ValueError(
                f"embed_text expects a list of strings, got {texts!r}; wrap a single prompt "
                "in a list: embed_text([prompt])"
            )
        missing = [text for text in dict.fromkeys(texts) if text not in self._text_cache]
        if missing:
            with torch.no_grad():
                embeddings = self._encode_text(missing).float().cpu()
            self._text_cache.update(zip(missing, embeddings, strict=True))
        if not texts:
            return torch.empty(0, self.dim, device=self.device)
        return torch.stack([self._text_cache[text] for text in texts]).to(self.device)

    def clear_text_cache(self) -> None:
        """Forget the cached prompt embeddings (done automatically when weights are replaced)."""
        self._text_cache.clear()

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        """Embed prompts that are not cached yet; returns ``[len(texts), dim]``."""
        raise NotImplementedError

    def extra_repr(self) -> str:
        return f"name={self.name!r}, dim={self.dim}, input_key={self.input_key!r}"
