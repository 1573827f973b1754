"""Trainable reward heads f_{W_I} (image) and f_{W_L} (text) on top of the frozen VLM.

Thesis section 3.1.3 (FuRL) attaches an MLP head to each VLM encoder; sections 4.2 and 4.3 use one
pair for the positional reward (f^P) and another for the directional reward (f^D).
"""

from __future__ import annotations

from torch import nn

from temporal_torchrl.rewards.registry import IMAGE_INPUTS, image_input_of


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
    """Input sizes ``(image_dim, text_dim)`` of the heads for a registered reward variant.

    The image input follows the layout the variant was registered with
    (:func:`~temporal_torchrl.rewards.register_reward`): ``"concatenated"`` variants (D3-D5) feed
    the image head the normalised position part and the normalised direction part (thesis
    4.3.2), ``2 * embedding_dim`` long; ``"embedding"`` variants read one embedding (or a
    difference of two), ``embedding_dim`` long. The text head always reads ``embedding_dim``.

    Raises:
        ValueError: for a zero-shot variant (``"liv"``: no heads) or an unknown variant.
    """
    if not isinstance(embedding_dim, int) or embedding_dim < 1:
        raise ValueError(f"embedding_dim={embedding_dim!r}; expected a positive integer.")
    layout = image_input_of(variant)  # Raises for an unknown or unregistered name.
    if layout is None:
        headed = [name for name, value in IMAGE_INPUTS.items() if value is not None]
        raise ValueError(f"Reward variant {variant!r} is zero-shot (registered with "
                         f"image_input=None) and has no heads; variants with heads: "
                         f"{', '.join(headed)}.")
    image_dim = 2 * embedding_dim if layout == "concatenated" else embedding_dim
    return image_dim, embedding_dim
