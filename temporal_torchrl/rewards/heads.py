"""Trainable reward heads f_{W_I} (image) and f_{W_L} (text) on top of the frozen VLM.

Thesis section 3.1.3 (FuRL) attaches an MLP head to each VLM encoder; sections 4.2 and 4.3 use one
pair for the positional reward (f^P) and another for the directional reward (f^D). Rewards that
read a window of embeddings (beyond the thesis, section 6.3 proposal) get a small sequence encoder
(:class:`SequenceEncoder`) as their image head.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from temporal_torchrl.modules import ReLU, relu
from temporal_torchrl.rewards.registry import IMAGE_INPUTS, registered


def _mlp(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    # No final activation or normalisation layer: the rewards normalise the outputs themselves.
    return nn.Sequential(nn.Linear(in_dim, hidden_dim), ReLU(), nn.Linear(hidden_dim, out_dim))


class SequenceEncoder(nn.Module):
    """A one-layer Transformer encoder over a short sequence of tokens, pooled to one vector
    (beyond the thesis, section 6.3 proposal: "a short-horizon sequence encoder, like a
    Transformer").

    h = mean_j TransformerLayer(W_e x_j + e_j),  f(x_1 .. x_L) = MLP(h)

    with a linear token embedding W_e to ``width``, learned position embeddings e_j (the order of
    the movements is what the encoder is for), one pre-norm encoder layer (``heads`` attention
    heads, feed-forward ``hidden_dim``, no dropout: the reward is deterministic) and the heads'
    MLP ``width -> hidden_dim -> ReLU -> out_dim`` after the mean over the tokens.

    Args:
        token_dim: size of each token (2·D for d_sequence: position part ⊕ step direction).
        length: number of tokens L (K - 1 for a window of K embeddings).
        hidden_dim, out_dim: as :class:`RewardHeads`.
        width: model width of the encoder layer.
        heads: attention heads (``width`` must be divisible by it).

    Example:
        >>> encoder = SequenceEncoder(token_dim=32, length=7)
        >>> encoder(torch.zeros(4, 7, 32)).shape
        torch.Size([4, 64])
    """

    def __init__(self, token_dim: int, length: int, hidden_dim: int = 256, out_dim: int = 64,
                 width: int = 64, heads: int = 4):
        super().__init__()
        for name, value in (("token_dim", token_dim), ("length", length), ("width", width),
                            ("heads", heads)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"SequenceEncoder: {name}={value!r}; expected a positive "
                                 "integer.")
        if width % heads:
            raise ValueError(f"SequenceEncoder: width={width} is not divisible by heads={heads}.")
        self.token_dim = token_dim
        self.length = length
        self.embed = nn.Linear(token_dim, width)
        # Small initial position embeddings, as in ViT/BERT: they start as a mild order signal.
        self.position_embedding = nn.Parameter(0.02 * torch.randn(length, width))
        self.layer = nn.TransformerEncoderLayer(width, heads, dim_feedforward=hidden_dim,
                                                dropout=0.0, batch_first=True, norm_first=True)
        self.output = _mlp(width, hidden_dim, out_dim)

    def forward(self, tokens: Tensor) -> Tensor:
        """``tokens [..., L, token_dim]`` -> ``[..., out_dim]``."""
        if tokens.shape[-2:] != (self.length, self.token_dim):
            raise ValueError(f"SequenceEncoder: tokens of shape {tuple(tokens.shape)}; expected "
                             f"[..., {self.length}, {self.token_dim}] (a window of "
                             f"{self.length + 1} embeddings).")
        return self._encode(self.embed(tokens))

    def forward_with_context(self, context: Tensor, tokens: Tensor,
                             token_norms: Tensor | None = None) -> Tensor:
        """:meth:`forward` of the tokens ``context ⊕ tokens_j``, j = 1 .. L, for one
        ``context [..., C]`` shared by a sequence's ``tokens [..., L, token_dim - C]``; with
        ``token_norms [..., L, 1]``, of the tokens ``context ⊕ tokens_j / token_norms_j``.

        The same function, cheaper: W_e splits into the columns that read the context and
        those that read the token, so the context's share of the token embedding is computed
        once per sequence instead of once per token, and the tokens are never concatenated.
        The division by ``token_norms`` runs on the tokens' embeddings (``width`` wide) instead
        of on the tokens. Tokens broadcast over the sequence (stride 0 along L, as ``expand``
        makes them, with their norms broadcast too: the straight path of
        :func:`~temporal_torchrl.rewards.directional.d_sequence`) are embedded once.
        """
        context_dim = context.shape[-1]
        if tokens.shape[-2] != self.length or context_dim + tokens.shape[-1] != self.token_dim:
            raise ValueError(f"SequenceEncoder: a context of size {context_dim} and tokens of "
                             f"shape {tuple(tokens.shape)}; expected [..., {self.length}, "
                             f"{self.token_dim}] together (a window of {self.length + 1} "
                             "embeddings).")
        if token_norms is not None and token_norms.shape[-2:] != (self.length, 1):
            raise ValueError(f"SequenceEncoder: token_norms of shape {tuple(token_norms.shape)}; "
                             f"expected [..., {self.length}, 1] (one norm per token, as "
                             "x.norm(dim=-1, keepdim=True) gives).")
        context_weight, token_weight = self.embed.weight.split(
            [context_dim, self.token_dim - context_dim], dim=-1)
        if tokens.stride(-2) == 0 and (token_norms is None or token_norms.stride(-2) == 0):
            tokens = tokens[..., :1, :]
            token_norms = None if token_norms is None else token_norms[..., :1, :]
        embedded = F.linear(tokens, token_weight)
        if token_norms is not None:
            embedded = embedded / token_norms
        hidden = embedded + self.embed.bias + F.linear(context, context_weight).unsqueeze(-2)
        return self._encode(hidden.expand(*hidden.shape[:-2], self.length, hidden.shape[-1]))

    def _encode(self, hidden: Tensor) -> Tensor:
        """Embedded tokens ``[..., L, width]`` -> ``[..., out_dim]``."""
        batch, width = hidden.shape[:-2], hidden.shape[-1]
        hidden = hidden.reshape(-1, self.length, width) + self.position_embedding
        return self.output(self._encoder_layer(hidden).mean(-2)).reshape(*batch, -1)

    def _encoder_layer(self, x: Tensor) -> Tensor:
        """``self.layer(x)`` (pre-norm, ReLU, no dropout), written out on its parameters.

        The same function, cheaper: ``nn.MultiheadAttention`` runs SDPA's CPU flash kernel,
        which on sequences this short costs more than the attention's own products.
        """
        layer, attention = self.layer, self.layer.self_attn
        rows, length, width = x.shape
        heads = attention.num_heads
        h = layer.norm1(x)
        q, k, v = (F.linear(h, attention.in_proj_weight, attention.in_proj_bias)
                   .view(rows, length, 3, heads, width // heads).permute(2, 0, 3, 1, 4))
        weights = torch.softmax(q @ k.transpose(-1, -2) * (width // heads) ** -0.5, dim=-1)
        attended = (weights @ v).transpose(1, 2).reshape(rows, length, width)
        x = x + attention.out_proj(attended)
        return x + layer.linear2(relu(layer.linear1(layer.norm2(x))))

    def extra_repr(self) -> str:
        return f"token_dim={self.token_dim}, length={self.length}"


class RewardHeads(nn.Module):
    """An image head and a text head, each an MLP ``in -> hidden -> ReLU -> out``; with
    ``sequence_length`` the image head is a :class:`SequenceEncoder` over that many tokens.

    Args:
        image_dim: input size of the image head (D, or 2·D for D3-D5; see :func:`heads_input_dims`);
            with ``sequence_length``, the size of each token.
        text_dim: input size of the text head (D).
        hidden_dim: hidden width (256 in the thesis's release).
        out_dim: output size (64 in the thesis's release).
        sequence_length: None (an MLP image head) or the number of tokens the image head reads
            (K - 1 for a ``"window"`` reward of K embeddings).

    Example:
        >>> import torch
        >>> heads = RewardHeads(*heads_input_dims("d3", 16))
        >>> heads.image(torch.zeros(4, 32)).shape, heads.text(torch.zeros(16)).shape
        (torch.Size([4, 64]), torch.Size([64]))
    """

    def __init__(self, image_dim: int, text_dim: int, hidden_dim: int = 256, out_dim: int = 64,
                 sequence_length: int | None = None):
        super().__init__()
        for name, value in (("image_dim", image_dim), ("text_dim", text_dim),
                            ("hidden_dim", hidden_dim), ("out_dim", out_dim)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"RewardHeads: {name}={value!r}; expected a positive integer.")
        self.image_dim = image_dim
        self.text_dim = text_dim
        self.sequence_length = sequence_length
        self.image = (_mlp(image_dim, hidden_dim, out_dim) if sequence_length is None else
                      SequenceEncoder(image_dim, sequence_length, hidden_dim, out_dim))
        self.text = _mlp(text_dim, hidden_dim, out_dim)

    def extra_repr(self) -> str:
        sequence = ("" if self.sequence_length is None
                    else f", sequence_length={self.sequence_length}")
        return f"image_dim={self.image_dim}, text_dim={self.text_dim}{sequence}"


def heads_input_dims(variant: str, embedding_dim: int) -> tuple[int, int]:
    """Input sizes ``(image_dim, text_dim)`` of the heads for a registered reward variant.

    The image input follows the layout the variant was registered with
    (:func:`~temporal_torchrl.rewards.register_reward`): ``"concatenated"`` variants (D3-D5) feed
    the image head the normalised position part and the normalised direction part (thesis
    4.3.2), ``2 * embedding_dim`` long; ``"window"`` variants (d_sequence) feed it a sequence of
    such concatenations, each token ``2 * embedding_dim`` long; ``"embedding"`` variants read
    one embedding (or a difference of two), ``embedding_dim`` long. The text head always reads
    ``embedding_dim``.

    Raises:
        ValueError: for a zero-shot variant (``"liv"``: no heads) or an unknown variant.
    """
    if not isinstance(embedding_dim, int) or embedding_dim < 1:
        raise ValueError(f"embedding_dim={embedding_dim!r}; expected a positive integer.")
    layout = registered(variant).image_input  # Raises for an unknown name.
    if layout is None:
        headed = [name for name, value in IMAGE_INPUTS.items() if value is not None]
        raise ValueError(f"Reward variant {variant!r} is zero-shot (registered with "
                         f"image_input=None) and has no heads; variants with heads: "
                         f"{', '.join(headed)}.")
    image_dim = 2 * embedding_dim if layout in ("concatenated", "window") else embedding_dim
    return image_dim, embedding_dim
