"""Any open_clip model as a frozen image/text :class:`Encoder`.

The model's image tower embeds frames (after :class:`ImagePreprocessor`), its text tower embeds
prompts tokenised by open_clip's tokenizer for that model. Embeddings are returned as the towers
produce them, NOT L2-normalised: the rewards normalise where the thesis's equations do.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import open_clip
import torch
from open_clip import pretrained as open_clip_pretrained
from torch import nn

from temporal_torchrl.encoders.base import Encoder
from temporal_torchrl.encoders.preprocessing import ImagePreprocessor, make_preprocessor

_SHOWN_CHARS = 200
#: How many names an error message lists before '... and N more'.
LISTED_NAMES = 10


class PretrainedWeightsUnavailableError(FileNotFoundError, RuntimeError):
    """open_clip's weights for a pretrained tag are neither cached nor downloadable (offline).

    A :class:`FileNotFoundError` (as LIV's offline error) and a :class:`RuntimeError` (what
    open_clip itself raises for a failed download), so either ``except`` catches it.
    """


def _first_line(error: BaseException) -> str:
    text = str(error).splitlines()[0] if str(error) else ""
    return text if len(text) <= _SHOWN_CHARS else text[:_SHOWN_CHARS] + "..."


def _fetch_pretrained(model_name: str, pretrained: str, cache_dir: str | None) -> None:
    """Make sure the weights of ``pretrained`` (a tag or a file) are on this machine.

    Raises:
        ValueError: ``pretrained`` is neither a file nor a tag open_clip knows for ``model_name``.
        PretrainedWeightsUnavailableError: the tag's weights are neither cached nor downloadable.
    """
    config = open_clip_pretrained.get_pretrained_cfg(model_name, pretrained)
    if not config:
        if os.path.isfile(pretrained):
            return
        tags = open_clip.list_pretrained_tags_by_model(model_name)
        raise ValueError(
            f"unknown open_clip pretrained tag {pretrained!r} for {model_name!r} (and not a "
            f"file); pick one of open_clip.list_pretrained_tags_by_model({model_name!r}): "
            f"{tags}, pass pretrained=None for random weights, or checkpoint=<file> for local "
            "weights"
        )
    try:
        open_clip_pretrained.download_pretrained(config, cache_dir=cache_dir)
    except OSError as error:
        hub = config.get("hf_hub", "") if open_clip_pretrained.has_hf_hub() else ""
        if hub:
            repo, filename = os.path.split(hub)
            filename = filename or open_clip_pretrained.HF_WEIGHTS_NAME
            source = (f"the file {filename!r} of the Hugging Face Hub repository {repo!r}, "
                      "and it is neither in the Hugging Face cache "
                      f"({cache_dir or 'HF_HOME'})")
            fetch = (f"run `hf download {repo} {filename}` or fetch "
                     f"https://huggingface.co/{repo}/resolve/main/{filename}")
        else:
            url = config.get("url", "")
            filename = os.path.basename(url)
            source = (f"the file {url}, and it is neither in open_clip's cache "
                      f"({cache_dir or '~/.cache/clip'})")
            fetch = f"fetch {url}"
        raise PretrainedWeightsUnavailableError(
            f"open_clip's pretrained weights {pretrained!r} for {model_name!r} are needed: "
            f"{source} nor downloadable from here: the machine seems offline "
            f"({type(error).__name__}: {_first_line(error)}). On a machine with internet "
            f"{fetch}, copy it over and pass its path: load_encoder('open_clip', "
            f"model_name={model_name!r}, checkpoint='/path/to/{filename}') (recipe: "
            f"encoder.checkpoint=/path/to/{filename} +encoder.options.model_name={model_name}); "
            "or run once where the Hugging Face Hub is reachable, which fills the cache"
        ) from error


class _DropRandomInitWarning(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "initialized randomly" not in record.getMessage()


@contextmanager
def quiet_random_init() -> Iterator[None]:
    """Silence open_clip's "initialized randomly" warning for a model whose weights come next."""
    log_filter = _DropRandomInitWarning()
    logging.getLogger().addFilter(log_filter)
    try:
        yield
    finally:
        logging.getLogger().removeFilter(log_filter)


def _listed(names: list[str]) -> str:
    shown = ", ".join(names[:LISTED_NAMES])
    more = len(names) - LISTED_NAMES
    return shown + (f" ... and {more} more" if more > 0 else "")


def state_dict_mismatch(model: nn.Module, state_dict: Mapping[str, torch.Tensor]) -> str | None:
    """The missing, unexpected and wrongly shaped entries of ``state_dict`` for ``model``, named
    (a few of each); None when it fits."""
    expected = model.state_dict()
    missing = [key for key in expected if key not in state_dict]
    unexpected = [key for key in state_dict if key not in expected]
    mismatched = [
        f"{key} (checkpoint {tuple(state_dict[key].shape)}, model {tuple(value.shape)})"
        for key, value in expected.items()
        if key in state_dict and tuple(state_dict[key].shape) != tuple(value.shape)
    ]
    problems = []
    if missing:
        problems.append(f"missing keys: {_listed(missing)}")
    if unexpected:
        problems.append(f"unexpected keys: {_listed(unexpected)}")
    if mismatched:
        problems.append(f"shape mismatches: {_listed(mismatched)}")
    return "; ".join(problems) or None


def _checkpoint_mismatch(model_name: str, checkpoint: str) -> ValueError:
    """The error for a ``checkpoint`` that does not fit ``model_name``: what differs, the fix."""
    state_dict = open_clip.factory.load_state_dict(checkpoint)
    if "liv" in state_dict:
        return ValueError(f"checkpoint {checkpoint!r} is LIV's model.pt (a dict with a 'liv' "
                          "entry): load it with load_encoder('liv', checkpoint=...) (recipe: "
                          "encoder.name=liv)")
    with quiet_random_init():
        model = open_clip.create_model(model_name)
    problems = state_dict_mismatch(model, state_dict)
    return ValueError(
        f"checkpoint {checkpoint!r} does not hold weights of open_clip's model_name="
        f"{model_name!r}: {problems}. Pass model_name= with the checkpoint's architecture (one "
        "of open_clip.list_models(); for LIV-style RN50 weights model_name='RN50-quickgelu', in "
        "the recipe +encoder.options.model_name=RN50-quickgelu)")


class OpenCLIPEncoder(Encoder):
    """A frozen open_clip model: frames and prompts into its joint embedding space.

    Args:
        model_name: an open_clip architecture, e.g. ``"ViT-B-32"`` (see
            ``open_clip.list_models()``).
        pretrained: an open_clip pretrained tag for that architecture, e.g. ``"openai"`` or
            ``"laion2b_s34b_b79k"`` (see ``open_clip.list_pretrained()``); downloaded into
            open_clip's cache on first use (offline, from the cache only).
        checkpoint: a local weights file instead of ``pretrained`` (loaded with
            ``weights_only=True``); it must hold ``model_name``'s architecture.
        preprocessing: ``None`` uses the model's own size, mean, std and interpolation on the
            tensor path (resize the shorter side, center crop; no antialiasing), or a preset
            name / :class:`ImagePreprocessor` (see :mod:`temporal_torchrl.encoders.preprocessing`).
        channels_last: keep the image tower and its input in channels-last memory format (faster
            convolutions on GPUs).
        cache_dir: where open_clip caches downloaded weights (default: its own).

    Raises:
        ValueError: an unknown ``model_name`` or ``pretrained`` tag, or a ``checkpoint`` whose
            weights do not fit ``model_name`` (the message names the first mismatches).
        FileNotFoundError: ``checkpoint`` is not a file.
        PretrainedWeightsUnavailableError: the ``pretrained`` tag's weights are neither cached
            nor downloadable (offline); the message says which file and how to pass a local copy.

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
        elif pretrained is not None:
            _fetch_pretrained(model_name, pretrained, cache_dir)
        try:
            model = open_clip.create_model(model_name, pretrained=weights, cache_dir=cache_dir,
                                           require_pretrained=weights is not None)
        except RuntimeError as error:
            if checkpoint is None or "state_dict" not in str(error):
                raise
            raise _checkpoint_mismatch(model_name, weights) from error
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

    @property
    def frame_size(self) -> int:
        return self.preprocess.frame_size

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
