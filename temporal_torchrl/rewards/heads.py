"""Trainable reward heads f_{W_I} (image) and f_{W_L} (text) on top of the frozen VLM.

Thesis section 3.1.3 (FuRL) attaches an MLP head to each VLM encoder; sections 4.2 and 4.3 use one
pair for the positional reward (f^P) and another for the directional reward (f^D).
"""

from __future__ import annotations

from torch import nn

#: Variants whose image head reads the concatenation of a position part and a direction part.
CONCATENATED_VARIANTS = ("d3", "d4", "d5")
#: Variants with trainable heads (``"liv"`` is zero-shot and has none).
HEADED_VARIANTS = ("furl", "p1", "p2", "p3", "p4", "d1", "d2", "d3", "d4", "d5")


def _mlp(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    # No final activation or normalisation layer: the rewards normalise the outputs themselves.
    return nn.Sequential(nn.Linear(in_dim, hidden_dim), nn.ReLU(), nn.Linear(hidden_dim, out_dim))


class RewardHeads(nn.Module):
    """An image head and a text head, each an MLP ``in -> hidden -> ReLU -> out``.

    Args:
        image_dim: input size of the image head (D, or 2·D for D3-D5; see :func:`heads_input_dims`).
        text_dim: input size of the text head (D).
        hidden_dim: hidden width (256 in the thesis's release).
        out_dim: output size (64 in the thesis's release).

    Example:
        >>> import torch
        >>> heads = RewardHeads(*heads_input_dims("d3", 16))
        >>> heads.image(torch.zeros(4, 32)).shape, heads.text(torch.zeros(16)).shape
        (torch.Size([4, 64]), torch.Size([64]))
    """

    def __init__(self, image_dim: int, text_dim: int, hidden_dim: int = 256, out_dim: int = 64):
        super().__init__()
        for name, value in (("image_dim", image_dim), ("text_dim", text_dim),
                            ("hidden_dim", hidden_dim), ("out_dim", out_dim)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"RewardHeads: {name}={value!r}; expected a positive integer.")
        self.image_dim = image_dim
        self.text_dim = text_dim
        self.image = _mlp(image_dim, hidden_dim, out_dim)
        self.text = _mlp(text_dim, hidden_dim, out_dim)

    def extra_repr(self) -> str:
        return f"image_dim={self.image_dim}, text_dim={self.text_dim}"


def heads_input_dims(variant: str, embedding_dim: int) -> tuple[int, int]:
    """Input sizes ``(image_dim, text_dim)`` of the heads for a reward variant.

    D3-D5 feed the image head the concatenation of the normalised position part and the
    normalised direction part (thesis 4.3.2), so their image input is ``2 * embedding_dim``; every
    other head reads one embedding (or a difference of two), ``embedding_dim`` long.

    Raises:
        ValueError: for ``"liv"`` (zero-shot, no heads) or an unknown variant.
    """
    if not isinstance(embedding_dim, int) or embedding_dim < 1:
        raise ValueError(f"embedding_dim={embedding_dim!r}; expected a positive integer.")
    if variant not in HEADED_VARIANTS:
        hint = " ('liv' is zero-shot and has no heads)" if variant == "liv" else ""
        raise ValueError(
            f"Unknown reward variant with heads {variant!r}{hint}; "
            f"expected one of {', '.join(HEADED_VARIANTS)}.")
    image_dim = 2 * embedding_dim if variant in CONCATENATED_VARIANTS else embedding_dim
    return image_dim, embedding_dim
