"""Frame preprocessing for CLIP-style image towers, batched, on tensors.

:class:`ImagePreprocessor` reproduces LIV's tensor path (Ma et al., 2023): frames scaled to
[0, 1], the shorter side resized to 224 with bilinear interpolation and no antialiasing, a
center crop of 224 x 224, then CLIP's mean/std normalisation. It takes uint8 ``[N, H, W, 3]``
frames of any size (the layout of the ``"pixels"`` key) and returns float32 ``[N, 3, 224, 224]``.

Two presets, picked by name in :func:`make_preprocessor`:

- ``"liv"`` (default): LIV's own path on the whole frame.
- ``"metaworld_prior"``: the prior Metaworld experiments' variant: frames rendered at 256 x 256
  are cropped to rows and columns ``[32:224]`` (192 x 192, the table and arm) before LIV's path,
  which then upsamples them to 224. Render with ``image_size=256`` for it.

Colour order: frames are fed as RGB. The prior code converted its frames RGB -> BGR before LIV
(a quirk, not a choice of LIV's); pass ``channel_order="bgr"`` to reproduce it exactly.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torchvision.transforms.functional as tvf
from torch import nn
from torchvision.transforms import InterpolationMode

CLIP_MEAN = (0.48145466, 0.4578275, 0.40821073)
CLIP_STD = (0.26862954, 0.26130258, 0.27577711)
METAWORLD_PRIOR_CROP = (32, 224, 32, 224)
PRESETS = ("liv", "metaworld_prior")
_INTERPOLATIONS = {"bilinear": InterpolationMode.BILINEAR, "bicubic": InterpolationMode.BICUBIC}


class ImagePreprocessor(nn.Module):
    """uint8 frames ``[N, H, W, 3]`` -> normalised float32 ``[N, 3, image_size, image_size]``.

    Args:
        image_size: side of the square the image tower expects (224 for LIV's RN50).
        crop_box: optional ``(row_start, row_stop, col_start, col_stop)`` cut from each frame
            before resizing (the prior Metaworld variant uses ``(32, 224, 32, 224)``).
        channel_order: ``"rgb"`` (default) or ``"bgr"`` (reverses the colour channels, as the
            prior Metaworld code did).
        interpolation: ``"bilinear"`` (LIV's tensor path) or ``"bicubic"``; never antialiased.
        mean, std: per-channel normalisation (CLIP's by default).
        channels_last: return the batch in channels-last memory format (faster convolutions on
            GPUs when the image tower is channels-last too).

    Example:
        >>> import torch
        >>> preprocess = ImagePreprocessor()
        >>> preprocess(torch.zeros(2, 64, 96, 3, dtype=torch.uint8)).shape
        torch.Size([2, 3, 224, 224])
    """

    def __init__(
        self,
        image_size: int = 224,
        *,
        crop_box: Sequence[int] | None = None,
        channel_order: str = "rgb",
        interpolation: str = "bilinear",
        mean: Sequence[float] = CLIP_MEAN,
        std: Sequence[float] = CLIP_STD,
        channels_last: bool = False,
    ) -> None:
        super().__init__()
        if channel_order not in ("rgb", "bgr"):
            raise ValueError(f"channel_order must be 'rgb' or 'bgr', got {channel_order!r}")
        if interpolation not in _INTERPOLATIONS:
            raise ValueError(
                f"interpolation must be one of {sorted(_INTERPOLATIONS)}, got {interpolation!r}"
            )
        if crop_box is not None:
            crop_box = tuple(int(v) for v in crop_box)
            if len(crop_box) != 4 or crop_box[0] >= crop_box[1] or crop_box[2] >= crop_box[3]:
                raise ValueError(
                    "crop_box must be (row_start, row_stop, col_start, col_stop) with "
                    f"start < stop, got {crop_box!r}"
                )
        self.image_size = int(image_size)
        self.crop_box = crop_box
        self.channel_order = channel_order
        self.interpolation = interpolation
        self.channels_last = channels_last
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1),
                             persistent=False)
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1),
                             persistent=False)

    @property
    def frame_size(self) -> int:
        """The frame side this preprocessing is made for: the crop box's extent when there is
        one (a smaller frame cannot hold it), else ``image_size``."""
        if self.crop_box is not None:
            return max(self.crop_box[1], self.crop_box[3])
        return self.image_size

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        if frames.dtype != torch.uint8 or frames.ndim != 4 or frames.shape[-1] != 3:
            raise ValueError(
                "expected uint8 RGB frames of shape [N, H, W, 3], got "
                f"{frames.dtype} {tuple(frames.shape)}; render with RenderTransform (uint8 "
                "[H, W, 3]) and flatten batch dimensions first"
            )
        frames = frames.to(self.mean.device, non_blocking=True)
        if self.crop_box is not None:
            row_start, row_stop, col_start, col_stop = self.crop_box
            if frames.shape[1] < row_stop or frames.shape[2] < col_stop:
                raise ValueError(
                    f"crop_box {self.crop_box} does not fit frames of size "
                    f"{tuple(frames.shape[1:3])}; the prior Metaworld crop needs frames rendered "
                    "at 256 x 256 (image_size=256)"
                )
            frames = frames[:, row_start:row_stop, col_start:col_stop]
        if self.channel_order == "bgr":
            frames = frames.flip(-1)
        # Scale to [0, 1] before resizing, as LIV does: bilinear resizing is linear, but the
        # float rounding then matches LIV's own order of operations.
        images = frames.permute(0, 3, 1, 2).float().div_(255.0)
        if min(images.shape[-2:]) != self.image_size:
            images = tvf.resize(images, [self.image_size],
                                interpolation=_INTERPOLATIONS[self.interpolation],
                                antialias=False)
        if tuple(images.shape[-2:]) != (self.image_size, self.image_size):
            images = tvf.center_crop(images, [self.image_size, self.image_size])
        images = (images - self.mean) / self.std
        if self.channels_last:
            images = images.contiguous(memory_format=torch.channels_last)
        return images

    def extra_repr(self) -> str:
        return (f"image_size={self.image_size}, crop_box={self.crop_box}, "
                f"channel_order={self.channel_order!r}, interpolation={self.interpolation!r}")


def make_preprocessor(preprocessing: str | ImagePreprocessor = "liv",
                      **kwargs: object) -> ImagePreprocessor:
    """An :class:`ImagePreprocessor` from a preset name (``"liv"``, ``"metaworld_prior"``).

    ``kwargs`` override the preset's settings, e.g. ``channel_order="bgr"``. An
    :class:`ImagePreprocessor` instance is returned unchanged.
    """
    if isinstance(preprocessing, ImagePreprocessor):
        return preprocessing
    if preprocessing == "liv":
        return ImagePreprocessor(**kwargs)
    if preprocessing == "metaworld_prior":
        return ImagePreprocessor(**{"crop_box": METAWORLD_PRIOR_CROP, **kwargs})
    raise ValueError(
        f"unknown preprocessing {preprocessing!r}; expected one of {PRESETS} or an "
        "ImagePreprocessor instance"
    )
