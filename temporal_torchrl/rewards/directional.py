"""Directional VLM rewards r_D (thesis 4.3): the value of the direction Δs_t = s_t - s_{t-k}.

Same registry signature as :mod:`temporal_torchrl.rewards.positional`:
``fn(heads, s, *, s0, s_prev, g, b, alpha, position=None, projection="origin") -> reward``.
The direction is always ``s - s_prev``; D3-D5 also read a position part computed from
``position`` (default ``s``). Passing the position separately lets the directional loss
(thesis 4.3.3) score any direction at a fixed position:

- observed direction: ``fn(heads, s_t, s_prev=s_{t-k})``
- towards the goal:   ``fn(heads, s_g, s_prev=s_t, position=s_t)``
- opposite direction: ``fn(heads, s_{t-k}, s_prev=s_t, position=s_t)``

Zero directions: at the start of an episode s_{t-k} = s_0 = s_t, so Δs_t = 0. Every normalisation
divides by max(||x||, eps) (:data:`~temporal_torchrl.rewards.positional.EPS`), which maps the zero
vector to zero: D1 and D3-D5 then feed the head a zero direction part (finite output), and D2's
zero image difference gives a reward of 0.
"""

from __future__ import annotations

import torch
from torch import Tensor

from temporal_torchrl.rewards.heads import RewardHeads
from temporal_torchrl.rewards.positional import (
    _required,
    cosine_similarity,
    goal_baseline_regularise,
    unit,
)
from temporal_torchrl.rewards.registry import DIRECTIONAL as DIRECTIONAL
from temporal_torchrl.rewards.registry import register_reward


def d1(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None, g: Tensor, b: Tensor,
       **unused) -> Tensor:
    """D1, direction before the heads (thesis 4.3.2):
    r_D1(Δs_t) = csim(f^D_{W_I}(s_t - s_{t-k}), f^D_{W_L}(g - b)).

    The direction is scaled to unit length before the image head (as in the thesis's release,
    4.3.3: the loss compares directions of very different magnitudes).
    """
    s_prev = _required(s_prev, "s_prev", "d1")
    return cosine_similarity(heads.image(unit(s - s_prev)), heads.text(g - b))


def d2(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None, g: Tensor, b: Tensor,
       **unused) -> Tensor:
    """D2, direction after the heads (thesis 4.3.2):
    r_D2(Δs_t) = csim(f^D_{W_I}(s_t) - f^D_{W_I}(s_{t-k}), f^D_{W_L}(g) - f^D_{W_L}(b)).
    """
    s_prev = _required(s_prev, "s_prev", "d2")
    image = heads.image(s) - heads.image(s_prev)
    return cosine_similarity(image, heads.text(g) - heads.text(b))


def _concatenated(heads: RewardHeads, position_part: Tensor, direction: Tensor, g: Tensor,
                  b: Tensor) -> Tensor:
    # Separate normalisation keeps position and direction equally weighted (thesis 4.3.2, last
    # paragraph); broadcasting lets either part be a single vector.
    position_part, direction = torch.broadcast_tensors(unit(position_part), unit(direction))
    image_input = torch.cat((position_part, direction), dim=-1)
    return cosine_similarity(heads.image(image_input), heads.text(g - b))


def d3(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None, g: Tensor, b: Tensor,
       position: Tensor | None = None, **unused) -> Tensor:
    """D3, position and direction (thesis 4.3.2):
    r_D3(s_t, Δs_t) = csim(f^D_{W_I}(s_t ⊕ Δs_t), f^D_{W_L}(g - b)),
    with s_t and Δs_t each scaled to unit length before the concatenation ⊕.
    The position s_t is ``position`` (default ``s``).
    """
    s_prev = _required(s_prev, "s_prev", "d3")
    position = s if position is None else position
    return _concatenated(heads, position, s - s_prev, g, b)


def d4(heads: RewardHeads, s: Tensor, *, s0: Tensor | None = None, s_prev: Tensor | None = None,
       g: Tensor, b: Tensor, position: Tensor | None = None, **unused) -> Tensor:
    """D4, delta-feature position and direction (thesis 4.3.2):
    r_D4(s_t, Δs_t) = csim(f^D_{W_I}((s_t - s_0) ⊕ Δs_t), f^D_{W_L}(g - b)),
    with s_t - s_0 and Δs_t each scaled to unit length before the concatenation.
    The position s_t is ``position`` (default ``s``).
    """
    s0 = _required(s0, "s0", "d4")
    s_prev = _required(s_prev, "s_prev", "d4")
    position = s if position is None else position
    return _concatenated(heads, position - s0, s - s_prev, g, b)


def d5(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None, g: Tensor, b: Tensor,
       alpha: float = 0.4, position: Tensor | None = None, projection: str = "origin",
       **unused) -> Tensor:
    """D5, goal-baseline-regularised position and direction (thesis 4.3.2):
    r_D5(s_t, Δs_t) = csim(f^D_{W_I}((alpha proj_L s_t + (1 - alpha) s_t) ⊕ Δs_t),
                           f^D_{W_L}(g - b)),
    L = g - b. The regularisation runs on the raw embeddings s_t, g and b (``projection="origin"``,
    as the thesis and its release write it; see
    :func:`~temporal_torchrl.rewards.positional.goal_baseline_regularise`); the regularised
    position and the direction are then each scaled to unit length before the concatenation.
    The position s_t is ``position`` (default ``s``).
    """
    s_prev = _required(s_prev, "s_prev", "d5")
    position = s if position is None else position
    regularised = goal_baseline_regularise(position, g, b, alpha, projection)
    return _concatenated(heads, regularised, s - s_prev, g, b)


# The built-in directional rewards, into DIRECTIONAL; d3-d5 read position ⊕ direction (2·D).
register_reward("d1", d1, kind="directional", image_input="embedding")
register_reward("d2", d2, kind="directional", image_input="embedding")
register_reward("d3", d3, kind="directional", image_input="concatenated")
register_reward("d4", d4, kind="directional", image_input="concatenated")
register_reward("d5", d5, kind="directional", image_input="concatenated")
