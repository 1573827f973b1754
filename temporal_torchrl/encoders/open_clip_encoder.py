"""Any open_clip model as a frozen image/text :class:`Encoder`.

The model's image tower embeds frames (after :class:`ImagePreprocessor`), its text tower embeds
prompts tokenised by open_clip's tokenizer for that model. Embeddings are returned as the towers
produce them, NOT L2-normalised: the rewards normalise where the thesis's equations do.
"""

from __future__ import annotations

from pathlib import Path

import open_clip
import torch
from torch import nn

from temporal_torchrl.encoders.base import Encoder
from temporal_torchrl.encoders.preprocessing import ImagePreprocessor, make_preprocessor


class OpenCLIPEncoder(Encoder):
    """A frozen open_clip model: frames and prompts into its joint embedding space.

    Args:
        model_name: an open_clip architecture, e.g. ``"ViT-B-32"`` (see
            ``open_clip.list_models()``).
        pretrained: an open_clip pretrained tag for that architecture, e.g. ``"openai"`` or
            ``"laion2b_s34b_b79k"`` (see ``open_clip.list_pretrained()``); downloaded into
            open_clip's cache on first use.
        checkpoint: a local weights file instead of ``pretrained`` (loaded with
            ``weights_only=True``).
        preprocessing: ``None`` uses the model's own size, mean, std and interpolation on the
            tensor path (resize the shorter side, center crop; no antialiasing), or a preset
            name / :class:`ImagePreprocessor` (see :mod:`temporal_torchrl.encoders.preprocessing`).
        channels_last: keep the image tower and its input in channels-last memory format (faster
            convolutions on GPUs).
        cache_dir: where open_clip caches downloaded weights (default: its own).

    Example:
        >>> encoder = OpenCLIPEncoder("ViT-B-32", pretrained="openai")  # doctest: +SKIP
        >>> encoder.embed_text(["open the drawer"]).shape  # doctest: +SKIP
        torch.Size([1, 512])
    """

    name = "open_clip"
    input_key = "pixels"

    def __init__(
        self,
        model_name: str = "ViT-B-32",
        pretrained: str | None = "openai",
        *,
        checkpoint: str | Path | None = None,
        preprocessing: str | ImagePreprocessor | None = None,
        channels_last: bool = False,
        cache_dir: str | None = None,
    ) -> None:
        super().__init__()
        if model_name not in open_clip.list_models():
            raise ValueError(
                f"unknown open_clip model {model_name!r}; pick one of open_clip.list_models(), "
                "e.g. 'ViT-B-32' or 'RN50-quickgelu'"
            )
        weights = pretrained
        if checkpoint is not None:
            if not Path(checkpoint).is_file():
                raise FileNotFoundError(
                    f"checkpoint {str(checkpoint)!r} is not a file; pass the path of a weights "
                    f"file for {model_name!r}, or checkpoint=None with a pretrained tag"
                )
            weights = str(checkpoint)
        model = open_clip.create_model(model_name, pretrained=weights, cache_dir=cache_dir,
                                       require_pretrained=weights is not None)
        if preprocessing is None:
            config = model.visual.preprocess_cfg
            size = config["size"]
            preprocessing = ImagePreprocessor(
                size if isinstance(size, int) else size[0],
                mean=config["mean"], std=config["std"],
                interpolation=config.get("interpolation", "bicubic"),
            )
        self._setup(model, model_name, preprocessing, channels_last)

    def _setup(self, model: nn.Module, model_name: str,
               preprocessing: str | ImagePreprocessor, channels_last: bool) -> None:
        """Attach a fully loaded open_clip ``model``, its tokenizer and the preprocessing."""
        self.model_name = model_name
        self.channels_last = channels_last
        self.preprocess = make_preprocessor(preprocessing)
        if channels_last:
            self.preprocess.channels_last = True
        self.tokenizer = open_clip.get_tokenizer(model_name)
        self._install(model)

    def _install(self, model: nn.Module) -> None:
        """Make ``model`` (fully loaded) the encoder's model: float32, frozen, cached text reset."""
        model = model.float()
        if self.channels_last:
            model.visual.to(memory_format=torch.channels_last)
        self.model = model.to(self.device if hasattr(self, "model") else "cpu")
        self.dim = int(model.text_projection.shape[-1])
        self.freeze()
        self.clear_text_cache()

    @property
    def device(self) -> torch.device:
        return self.model.logit_scale.device if hasattr(self, "model") else torch.device("cpu")

    def preprocess_images(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 frames ``[N, H, W, 3]`` -> the image tower's input ``[N, 3, S, S]``."""
        return self.preprocess(frames)

    def embed_preprocessed(self, images: torch.Tensor) -> torch.Tensor:
        """The image tower on already preprocessed images ``[N, 3, S, S]`` -> ``[N, dim]``."""
        with torch.no_grad():
            return self.model.encode_image(images).float()

    def embed_images(self, frames: torch.Tensor) -> torch.Tensor:
        """Embed uint8 RGB frames ``[N, H, W, 3]`` (any size) into float32 ``[N, dim]``."""
        return self.embed_preprocessed(self.preprocess_images(frames))

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        tokens = self.tokenizer(texts).to(self.device)
        return self.model.encode_text(tokens)

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, model_name={self.model_name!r}"
