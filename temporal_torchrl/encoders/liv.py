"""LIV (Ma et al., ICML 2023) on open_clip: the real checkpoint, loaded faithfully.

LIV is an unmodified OpenAI CLIP RN50 fine-tuned on robot videos. open_clip's
``RN50-quickgelu`` architecture matches its weights key for key (plain ``RN50`` uses GELU: it
loads without complaint and gives different text embeddings). Both towers output 1024-d
embeddings that are not L2-normalised; LIV compares them by cosine similarity.

The weights are the ``"liv"`` entry of ``model.pt`` in the Hugging Face Hub repository
``jasonyma/LIV``: a plain dict of 489 tensors named ``module.model.<open_clip name>``, with
convolution/linear/attention weights in fp16 and norms/embeddings in fp32. They are loaded with
``torch.load(weights_only=True)`` (nothing is unpickled as code), the prefix is stripped, the
keys and shapes are checked against a freshly built model, the dict is loaded strictly into that
model, which is cast to float32, put in eval mode and only then swapped in: a bad checkpoint
leaves an encoder exactly as it was.

Getting the checkpoint:

- With internet: ``load_encoder("liv")`` downloads ``model.pt`` (255 MB) once into the Hugging
  Face cache (``HF_HOME``) and reuses it afterwards, also offline.
- Without: download it elsewhere (``hf download jasonyma/LIV model.pt``, or
  https://huggingface.co/jasonyma/LIV/resolve/main/model.pt), copy it over and pass
  ``load_encoder("liv", checkpoint="/path/to/model.pt")``.

Example (random weights in LIV's on-disk format, as the tests and benchmarks use):
    >>> import tempfile, torch
    >>> path = tempfile.mkdtemp() + "/model.pt"
    >>> _ = save_random_liv_checkpoint(path)
    >>> encoder = LIVEncoder(checkpoint=path)
    >>> encoder.embed_images(torch.zeros(1, 64, 64, 3, dtype=torch.uint8)).shape
    torch.Size([1, 1024])
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import open_clip
import torch
from torch import nn

from temporal_torchrl.encoders.open_clip_encoder import (
    LISTED_NAMES,
    OpenCLIPEncoder,
    quiet_random_init,
    state_dict_mismatch,
)
from temporal_torchrl.encoders.preprocessing import ImagePreprocessor

LIV_ARCHITECTURE = "RN50-quickgelu"
LIV_HUB_REPO = "jasonyma/LIV"
LIV_HUB_FILENAME = "model.pt"
LIV_CHECKPOINT_ENTRY = "liv"
LIV_KEY_PREFIX = "module.model."


def build_liv_architecture() -> nn.Module:
    """A randomly initialised open_clip ``RN50-quickgelu`` (LIV's architecture), float32."""
    with quiet_random_init():
        return open_clip.create_model(LIV_ARCHITECTURE, pretrained=None)


def resolve_liv_checkpoint(checkpoint: str | os.PathLike | None = None, *,
                           revision: str | None = None, cache_dir: str | None = None) -> Path:
    """The path of LIV's ``model.pt``: ``checkpoint`` if given, else the Hub's (cached) copy.

    Raises:
        FileNotFoundError: ``checkpoint`` is not a file, or the Hub file is neither cached nor
            downloadable (offline); the message says which file is needed, from where, and how
            to pass a local copy instead.
    """
    if checkpoint is not None:
        path = Path(checkpoint).expanduser()
        if not path.is_file():
            raise FileNotFoundError(
                f"LIV checkpoint {str(checkpoint)!r} is not a file; pass the path of LIV's "
                f"model.pt (from https://huggingface.co/{LIV_HUB_REPO}), or checkpoint=None to "
                "download it from the Hugging Face Hub"
            )
        return path
    from huggingface_hub import hf_hub_download
    from huggingface_hub.errors import HfHubHTTPError, LocalEntryNotFoundError

    try:
        return Path(hf_hub_download(repo_id=LIV_HUB_REPO, filename=LIV_HUB_FILENAME,
                                    revision=revision, cache_dir=cache_dir))
    except (LocalEntryNotFoundError, HfHubHTTPError, OSError) as error:
        raise FileNotFoundError(
            f"LIV's weights are needed: the file {LIV_HUB_FILENAME!r} (255 MB) of the Hugging "
            f"Face Hub repository {LIV_HUB_REPO!r}, and it is neither in the Hugging Face cache "
            "nor downloadable from here "
            f"({type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}). "
            f"On a machine with internet run `hf download {LIV_HUB_REPO} {LIV_HUB_FILENAME}` "
            f"(older huggingface_hub: `huggingface-cli download ...`) or fetch "
            f"https://huggingface.co/{LIV_HUB_REPO}/resolve/main/{LIV_HUB_FILENAME}, then "
            "either put it in this machine's Hugging Face cache (HF_HOME) or pass its path: "
            "load_encoder('liv', checkpoint='/path/to/model.pt')"
        ) from error


def load_liv_state_dict(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """LIV's weights from ``model.pt``: the ``"liv"`` entry with ``module.model.`` stripped.

    Loaded with ``torch.load(weights_only=True)`` on the CPU; dtypes are kept as stored.
    """
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise ValueError(
            f"could not read {str(path)!r} as a weights-only torch checkpoint "
            f"({type(error).__name__}: {error}); expected LIV's model.pt from "
            f"https://huggingface.co/{LIV_HUB_REPO}"
        ) from error
    if not isinstance(checkpoint, Mapping) or LIV_CHECKPOINT_ENTRY not in checkpoint:
        found = list(checkpoint)[:LISTED_NAMES] if isinstance(checkpoint, Mapping) else (
            type(checkpoint).__name__)
        raise ValueError(
            f"{str(path)!r} is not a LIV checkpoint: expected a dict with a "
            f"{LIV_CHECKPOINT_ENTRY!r} entry (LIV's model.pt), found {found}"
        )
    return {
        key.removeprefix(LIV_KEY_PREFIX): value
        for key, value in checkpoint[LIV_CHECKPOINT_ENTRY].items()
    }


def check_state_dict(model: nn.Module, state_dict: Mapping[str, torch.Tensor],
                     source: str = "checkpoint") -> None:
    """Raise a ValueError naming every missing, unexpected or wrongly shaped entry."""
    problems = state_dict_mismatch(model, state_dict)
    if problems:
        raise ValueError(
            f"{source} does not match open_clip's {LIV_ARCHITECTURE!r} (LIV's architecture; key "
            f"names shown without the {LIV_KEY_PREFIX!r} prefix): {problems}. Pass LIV's own "
            f"model.pt from https://huggingface.co/{LIV_HUB_REPO}"
        )


def build_liv_model(state_dict: Mapping[str, torch.Tensor], source: str = "checkpoint"
                    ) -> nn.Module:
    """A fresh ``RN50-quickgelu`` holding ``state_dict`` (strictly), float32, in eval mode."""
    model = build_liv_architecture()
    check_state_dict(model, state_dict, source)
    model.load_state_dict({key: value.float() for key, value in state_dict.items()}, strict=True)
    return model.float().eval()


def save_random_liv_checkpoint(path: str | os.PathLike, *, seed: int = 0) -> nn.Module:
    """Write random weights in LIV's exact on-disk format; return the model they come from.

    For tests and benchmarks where the real weights cannot be downloaded. The file holds
    ``{"liv": {"module.model.<name>": tensor}}`` with convolution, linear and attention weights
    in fp16 (as OpenAI's ``convert_weights`` leaves them) and norms and embeddings in fp32.
    BatchNorm statistics are randomised too, so a loader that dropped them would be caught.
    The returned float32 model carries the same fp16-rounded values as the file, in eval mode.
    """
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_liv_architecture()
        for module in model.modules():
            if isinstance(module, nn.BatchNorm2d):
                module.running_mean.normal_(0.0, 0.1)
                module.running_var.uniform_(0.5, 1.5)
    half = set()
    for module_name, module in model.named_modules():
        prefix = f"{module_name}." if module_name else ""
        if isinstance(module, (nn.Conv1d, nn.Conv2d, nn.Linear)):
            half.update(f"{prefix}{name}" for name in ("weight", "bias"))
        elif isinstance(module, nn.MultiheadAttention):
            half.update(f"{prefix}{name}" for name in ("in_proj_weight", "in_proj_bias",
                                                       "bias_k", "bias_v", "q_proj_weight",
                                                       "k_proj_weight", "v_proj_weight"))
        for name in ("text_projection", "proj"):
            if isinstance(getattr(module, name, None), nn.Parameter):
                half.add(f"{prefix}{name}")
    stored = {
        key: value.half() if key in half and value.is_floating_point() else value
        for key, value in model.state_dict().items()
    }
    model.load_state_dict({key: value.float() for key, value in stored.items()})
    torch.save({LIV_CHECKPOINT_ENTRY: {LIV_KEY_PREFIX + key: value
                                       for key, value in stored.items()}}, path)
    return model.eval()


class LIVEncoder(OpenCLIPEncoder):
    """LIV's image and text towers as a frozen :class:`Encoder` (1024-d, not normalised).

    Args:
        checkpoint: path of LIV's ``model.pt``; ``None`` downloads it from the Hub
            (``jasonyma/LIV``) or reuses the Hugging Face cache.
        preprocessing: ``"liv"`` (LIV's own tensor path, default), ``"metaworld_prior"`` (the
            prior Metaworld experiments' 256 -> [32:224] crop), or an :class:`ImagePreprocessor`
            (e.g. ``make_preprocessor("metaworld_prior", channel_order="bgr")`` to reproduce
            the prior code's BGR input exactly).
        channels_last: channels-last image tower and input (faster on GPUs).
        revision, cache_dir: passed to ``huggingface_hub.hf_hub_download``.

    Example:
        >>> encoder = LIVEncoder()  # downloads model.pt once  # doctest: +SKIP
        >>> goal = encoder.embed_text(["open the drawer"])  # doctest: +SKIP
    """

    name = "liv"
    input_key = "pixels"

    def __init__(
        self,
        checkpoint: str | os.PathLike | None = None,
        *,
        preprocessing: str | ImagePreprocessor = "liv",
        channels_last: bool = False,
        revision: str | None = None,
        cache_dir: str | None = None,
    ) -> None:
        super(OpenCLIPEncoder, self).__init__()
        path = resolve_liv_checkpoint(checkpoint, revision=revision, cache_dir=cache_dir)
        model = build_liv_model(load_liv_state_dict(path), source=str(path))
        self.checkpoint_path = path
        self._setup(model, LIV_ARCHITECTURE, preprocessing, channels_last)

    def load_checkpoint(self, checkpoint: str | os.PathLike) -> LIVEncoder:
        """Swap in the weights of another LIV checkpoint; on any error the old ones stay."""
        path = resolve_liv_checkpoint(checkpoint)
        model = build_liv_model(load_liv_state_dict(path), source=str(path))
        self.checkpoint_path = path
        self._install(model)
        return self

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, checkpoint={str(self.checkpoint_path)!r}"
