"""Frozen encoders that embed observations and prompts into one space.

``load_encoder(name)`` builds one of :data:`ENCODERS`:

- ``"liv"``: LIV (open_clip ``RN50-quickgelu`` with LIV's weights; ``checkpoint`` is the path of
  its ``model.pt``, else it is downloaded from the Hugging Face Hub, ``jasonyma/LIV``).
- ``"open_clip"``: any open_clip model (``model_name=...``, ``pretrained=<tag>`` or
  ``checkpoint=<local file>``).
- ``"state"``: a render-free random projection of the state vector; NOT a vision-language model.
- ``"metaworld_small"``: the package's own small CNN image encoder and token-averaging text
  encoder, trained with LIV's objective on 44 Metaworld tasks (the six evaluation tasks held
  out); its weights ship in the package (``weights/MODEL_CARD.md``), so it needs no network.

Example:
    >>> from temporal_torchrl.encoders import load_encoder
    >>> encoder = load_encoder("state", dim=16)
    >>> encoder.embed_text(["open the drawer", "robot arm beside table"]).shape
    torch.Size([2, 16])
"""

from __future__ import annotations

import os
from typing import Any

import torch

from temporal_torchrl.encoders.base import Encoder
from temporal_torchrl.encoders.liv import LIVEncoder, save_random_liv_checkpoint
from temporal_torchrl.encoders.open_clip_encoder import OpenCLIPEncoder
from temporal_torchrl.encoders.preprocessing import ImagePreprocessor, make_preprocessor
from temporal_torchrl.encoders.small import SmallEncoder
from temporal_torchrl.encoders.state import StateEncoder

ENCODERS: tuple[str, ...] = ("liv", "open_clip", "state", "metaworld_small")


def load_encoder(name: str, *, checkpoint: str | os.PathLike | None = None,
                 device: str | torch.device = "cpu", **kwargs: Any) -> Encoder:
    """Build a frozen encoder by name, on ``device``.

    Args:
        name: one of :data:`ENCODERS`.
        checkpoint: a local weights file (``liv``: LIV's ``model.pt``; ``open_clip``: weights
            for ``model_name``). ``state`` takes none.
        device: where the encoder's weights live.
        **kwargs: passed to :class:`LIVEncoder`, :class:`OpenCLIPEncoder`,
            :class:`StateEncoder` or :class:`SmallEncoder` (e.g.
            ``preprocessing="metaworld_prior"``, ``model_name="ViT-B-32", pretrained="openai"``,
            ``dim=64``).
    """
    if name == "liv":
        encoder: Encoder = LIVEncoder(checkpoint, **kwargs)
    elif name == "open_clip":
        encoder = OpenCLIPEncoder(checkpoint=checkpoint, **kwargs)
    elif name == "state":
        if checkpoint is not None:
            raise ValueError(
                f"the 'state' encoder has no weights to load, got checkpoint={checkpoint!r}; "
                "pass seed=... to change its fixed random projection"
            )
        encoder = StateEncoder(**kwargs)
    elif name == "metaworld_small":
        # ``checkpoint=None`` loads the shipped weights.
        encoder = SmallEncoder.from_pretrained(checkpoint, **kwargs)
    else:
        raise ValueError(f"unknown encoder {name!r}; expected one of {ENCODERS}")
    return encoder.to(device)


__all__ = [
    "ENCODERS",
    "Encoder",
    "ImagePreprocessor",
    "LIVEncoder",
    "OpenCLIPEncoder",
    "SmallEncoder",
    "StateEncoder",
    "load_encoder",
    "make_preprocessor",
    "save_random_liv_checkpoint",
]
