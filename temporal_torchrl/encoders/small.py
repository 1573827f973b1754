"""The project's own small vision-language encoder, trained on Metaworld with LIV's objective.

LIV's RN50 embeds a few images per second on a CPU and its weights need the network. This
encoder is the offline, CPU-fast default: a compact CNN over 64x64 RGB frames and a bag of
open_clip token embeddings for text, both ending in the same ``D``-dimensional space where
cosine similarity is the value of a frame for a goal (LIV's zero-shot reward
``csim(image_embedding, text_embedding)``). Its weights ship inside the package
(``encoders/weights/metaworld_small.pt``, trained by ``recipes/pretrain_encoder.py`` on the
44 MT50 tasks that are not evaluation tasks; see ``encoders/weights/MODEL_CARD.md``).

Example:
    >>> import torch
    >>> from temporal_torchrl.encoders.small import SmallEncoder
    >>> encoder = SmallEncoder.from_pretrained()
    >>> frames = torch.randint(0, 256, (4, 224, 224, 3), dtype=torch.uint8)
    >>> encoder.embed_images(frames).shape
    torch.Size([4, 256])
    >>> encoder.embed_text(["open a drawer"]).shape
    torch.Size([1, 256])
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from temporal_torchrl.encoders.base import Encoder

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "metaworld_small.pt"
TOKENIZER_NAME = "RN50-quickgelu"
VOCABULARY_SIZE = 49408
# open_clip's start-of-text and end-of-text ids; with padding (0) they carry no content.
_SPECIAL_TOKENS = (0, 49406, 49407)


class SmallImageEncoder(nn.Module):
    """A compact CNN: uint8 frames of any size -> float32 embeddings ``[N, embedding_dim]``.

    The encoder resizes frames itself (bilinear, antialiased) to ``image_size`` so callers can
    render at any size; rendering at ``image_size`` skips the resize. Four stride-2 stages leave
    a 4x4 spatial map (for 64x64 input) that is flattened rather than pooled, because *where*
    the arm and the object are is what changes along a Metaworld episode.
    """

    def __init__(self, image_size: int = 64, embedding_dim: int = 256, width: int = 32) -> None:
        super().__init__()
        if image_size % 16 != 0 or image_size < 32:
            raise ValueError(
                f"image_size={image_size} is not supported: expected a multiple of 16 that is at "
                "least 32 (e.g. 64 or 96)."
            )
        self.image_size = image_size
        channels = [3, width, width * 2, width * 4, width * 4]
        layers: list[nn.Module] = []
        for index, (cin, cout) in enumerate(zip(channels[:-1], channels[1:], strict=True)):
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.ReLU(inplace=True)]
            if index == 1:
                # One extra conv at 1/4 resolution: more capacity where it is still cheap.
                layers += [nn.Conv2d(cout, cout, 3, padding=1), nn.ReLU(inplace=True)]
        self.features = nn.Sequential(*layers)
        spatial = image_size // 16
        self.projection = nn.Sequential(
            nn.Flatten(),
            nn.Linear(channels[-1] * spatial * spatial, 512),
            nn.ReLU(inplace=True),
            nn.Linear(512, embedding_dim),
            # Centres and scales each dimension over the training frames (running statistics
            # at inference). Without it, the ReLU features of all frames share one dominant
            # direction, every cosine similarity starts near 1 and the value objective barely
            # moves.
            nn.BatchNorm1d(embedding_dim, affine=False),
        )
        # Pixel statistics of Metaworld renders are close to these; exact values do not matter.
        self.register_buffer("mean", torch.tensor([0.5, 0.5, 0.5]).view(1, 3, 1, 1),
                             persistent=False)
        self.register_buffer("std", torch.tensor([0.25, 0.25, 0.25]).view(1, 3, 1, 1),
                             persistent=False)

    def preprocess(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 ``[N, H, W, 3]`` -> normalised float ``[N, 3, image_size, image_size]``."""
        if frames.dim() != 4 or frames.shape[-1] != 3:
            raise ValueError(
                f"frames have shape {tuple(frames.shape)}: expected uint8 [N, H, W, 3] RGB frames "
                "(add a batch dimension with frames[None] for a single frame)."
            )
        images = frames.permute(0, 3, 1, 2).float().div_(255.0)
        if images.shape[-2:] != (self.image_size, self.image_size):
            images = F.interpolate(images, size=(self.image_size, self.image_size),
                                   mode="bilinear", align_corners=False, antialias=True)
        return (images - self.mean) / self.std

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Normalised images ``[N, 3, S, S]`` (from :meth:`preprocess`) -> ``[N, D]``."""
        return self.projection(self.features(images))


class SmallTextEncoder(nn.Module):
    """Mean of learnt open_clip token embeddings followed by an MLP: texts -> ``[N, D]``.

    A bag of words is enough for Metaworld's short goal prompts ("open a drawer") and, unlike
    a transformer trained on a few dozen prompts, it composes seen words for unseen prompts.
    Tokens come from ``open_clip.get_tokenizer("RN50-quickgelu")`` (CLIP's BPE, bundled with
    open_clip, so it works offline).
    """

    def __init__(self, embedding_dim: int = 256, token_dim: int = 64) -> None:
        super().__init__()
        # Sparse gradients: a batch touches a few dozen of the 49408 rows, and a dense optimiser
        # step over the whole table would cost more than the rest of the model.
        self.token_embedding = nn.Embedding(VOCABULARY_SIZE, token_dim, sparse=True)
        nn.init.normal_(self.token_embedding.weight, std=0.02)
        self.projection = nn.Sequential(
            nn.Linear(token_dim, 256), nn.ReLU(inplace=True), nn.Linear(256, embedding_dim)
        )
        self._tokenizer: Any = None

    def tokenize(self, texts: list[str]) -> torch.Tensor:
        """``list[str]`` -> int64 token ids ``[N, 77]`` (CLIP BPE, zero-padded)."""
        if isinstance(texts, str) or not all(isinstance(text, str) for text in texts):
            raise ValueError(
                f"texts={texts!r} is not a list of strings: pass e.g. ['open a drawer']."
            )
        if self._tokenizer is None:
            import open_clip

            self._tokenizer = open_clip.get_tokenizer(TOKENIZER_NAME)
        return self._tokenizer(list(texts))

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Token ids ``[N, L]`` -> ``[N, D]``."""
        mask = torch.ones_like(tokens, dtype=torch.bool)
        for special in _SPECIAL_TOKENS:
            mask &= tokens != special
        mask = mask.unsqueeze(-1).float()
        words = self.token_embedding(tokens) * mask
        pooled = words.sum(dim=1) / mask.sum(dim=1).clamp_min(1.0)
        return self.projection(pooled)


class SmallEncoder(Encoder):
    """Image and text towers of the small Metaworld encoder behind the :class:`Encoder` API.

    Args:
        image_size: side of the square frames the CNN sees (frames are resized to it).
        embedding_dim: ``D``, the size of image and text embeddings.
        width: channels of the first CNN stage (later stages use 2x and 4x).
        token_dim: size of the learnt token embeddings of the text tower.
        name: the name runs record for this encoder.
    """

    input_key = "pixels"

    def __init__(self, image_size: int = 64, embedding_dim: int = 256, width: int = 32,
                 token_dim: int = 64, name: str = "metaworld_small") -> None:
        super().__init__()
        self.name = name
        self.dim = embedding_dim
        self.image_encoder = SmallImageEncoder(image_size, embedding_dim, width)
        self.text_encoder = SmallTextEncoder(embedding_dim, token_dim)

    @property
    def image_size(self) -> int:
        return self.image_encoder.image_size

    @property
    def frame_size(self) -> int:
        return self.image_size

    def config(self) -> dict[str, int | str]:
        """Constructor arguments, as saved next to the weights."""
        return {"image_size": self.image_size, "embedding_dim": self.dim,
                "width": self.image_encoder.features[0].out_channels,
                "token_dim": self.text_encoder.token_embedding.embedding_dim, "name": self.name}

    @torch.no_grad()
    def embed_images(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 ``[N, H, W, 3]`` RGB frames -> float32 ``[N, D]`` (not L2-normalised)."""
        images = self.image_encoder.preprocess(frames.to(self.device))
        return self.image_encoder(images).float()

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        tokens = self.text_encoder.tokenize(texts).to(self.device)
        return self.text_encoder(tokens)

    def save(self, path: str | Path, dtype: torch.dtype = torch.float16) -> None:
        """Write ``{"state_dict", "config"}`` loadable with ``torch.load(weights_only=True)``."""
        state_dict = {key: value.detach().to("cpu", dtype) if value.is_floating_point()
                      else value.detach().cpu() for key, value in self.state_dict().items()}
        torch.save({"state_dict": state_dict, "config": self.config()}, path)

    @classmethod
    def from_pretrained(cls, checkpoint: str | Path | None = None,
                        device: str | torch.device = "cpu") -> SmallEncoder:
        """Load a checkpoint written by :meth:`save` (default: the weights shipped here)."""
        path = Path(checkpoint) if checkpoint is not None else DEFAULT_WEIGHTS
        if not path.is_file():
            raise ValueError(
                f"checkpoint {str(path)!r} does not exist: expected a file written by "
                "SmallEncoder.save (train one with `python recipes/pretrain_encoder.py`), or "
                "checkpoint=None for the weights shipped in the package."
            )
        payload = torch.load(path, map_location="cpu", weights_only=True)
        if not isinstance(payload, dict) or {"state_dict", "config"} - payload.keys():
            raise ValueError(
                f"checkpoint {str(path)!r} is not a small-encoder checkpoint: expected a dict "
                "with 'state_dict' and 'config' as written by SmallEncoder.save."
            )
        encoder = cls(**payload["config"])
        state_dict = {key: value.float() if value.is_floating_point() else value
                      for key, value in payload["state_dict"].items()}
        encoder.load_state_dict(state_dict, strict=True)
        return encoder.to(device).freeze()
