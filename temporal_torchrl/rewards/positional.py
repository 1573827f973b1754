"""Positional VLM rewards r_P (thesis 3.1 and 4.2): the value of the current position s_t.

Every function has the registry signature
``fn(heads, s, *, s0, s_prev, g, b, alpha, position=None, projection="origin") -> reward``:
``s``, ``s0``, ``s_prev``, ``position`` are image embeddings ``[..., D]``, ``g`` and ``b`` the goal
and baseline text embeddings ``[D]``, the reward has shape ``s.shape[:-1]``. Arguments a variant
does not use are ignored. Text-side head outputs are computed once per call (``g`` and ``b`` are
single vectors) and broadcast over the batch.

Normalisation: csim(x, y) = x·y / (max(||x||, eps) max(||y||, eps)) with eps = :data:`EPS`, so a
zero vector (e.g. s_t - s_0 at t = 0 in P2) gives a reward of 0 instead of NaN.

Goal-baseline regularisation (thesis 3.1.2, eq. 4.5) replaces a vector x by
alpha proj_L x + (1 - alpha) x. Its two forms, chosen by ``projection``:

- ``"origin"`` (default; the thesis's equations and its release, which produced its tables):
  proj_L x = ((x·d) / (d·d)) d with d = g - b, the projection onto the direction g - b through
  the origin, applied to the vectors *as they are*. P4 and the D5 position therefore project the
  raw (unnormalised) LIV embedding s_t onto the raw g - b; P3 projects the unit head outputs
  f_I(s_t)/||f_I(s_t)|| onto f_L(g)/||f_L(g)|| - f_L(b)/||f_L(b)||, because the release
  normalises the head outputs before regularising.
- ``"line"`` (VLM-RMs, Rocamonde et al. 2024, the method's source paper): x, g and b are first
  scaled to unit length (VLM-RMs works with unit CLIP embeddings; a line through b and g is only
  meaningful when x, g and b share one scale) and proj_L x = b + (((x - b)·d) / (d·d)) d is the
  projection onto the line through b and g. Then 1 - 1/2 ||alpha proj_L x + (1 - alpha) x - g||^2
  equals VLM-RMs' 1 - 1/2 ||(x - g) P||^2 with P = alpha d d^T / ||d||^2 + (1 - alpha) I.

In both forms the regularised vector itself is *not* renormalised before the head (P4) or the
distance (P3): shrinking the components orthogonal to L is what makes the regularised reward
differ from csim.
"""

from __future__ import annotations

import torch
from torch import Tensor

from temporal_torchrl.defaults import ALPHA, PROJECTION, PROJECTIONS
from temporal_torchrl.rewards.heads import RewardHeads
from temporal_torchrl.rewards.registry import register_reward

#: Floor on vector norms in every normalisation (zero vectors map to zero, not NaN).
EPS = 1e-8


def clamped_norm(x: Tensor) -> Tensor:
    """max(||x||_2, EPS) along the last dimension, kept: the divisor of :func:`unit`."""
    return x.norm(dim=-1, keepdim=True).clamp_min(EPS)


def unit(x: Tensor) -> Tensor:
    """x / max(||x||_2, EPS) along the last dimension (zero vectors stay zero)."""
    return x / clamped_norm(x)


def cosine_similarity(x: Tensor, y: Tensor) -> Tensor:
    """csim(x, y) = x·y / (||x|| ||y||) over the last dimension, broadcasting ``y`` over ``x``."""
    return (unit(x) * unit(y)).sum(-1)


def goal_baseline_regularise(x: Tensor, goal: Tensor, baseline: Tensor, alpha: float,
                             projection: str = PROJECTION) -> Tensor:
    """alpha proj_L x + (1 - alpha) x (thesis 3.1.2, eq. 4.5), broadcast over ``x [..., D]``.

    ``projection="origin"``: L is the direction ``goal - baseline`` through the origin, on the
    vectors as given (no normalisation). ``projection="line"``: x, goal and baseline are scaled to
    unit length and L is the line through them (VLM-RMs). See the module docstring.
    """
    if projection not in PROJECTIONS:
        raise ValueError(f"projection={projection!r}; expected one of {', '.join(PROJECTIONS)}.")
    if projection == "line":
        x, goal, baseline = unit(x), unit(goal), unit(baseline)
    direction = goal - baseline
    # g == b leaves no direction; the clamp keeps the projection finite (it becomes 0 or b).
    scale_denominator = (direction @ direction).clamp_min(EPS * EPS)
    offset = baseline if projection == "line" else torch.zeros_like(baseline)
    coefficient = ((x - offset) @ direction) / scale_denominator
    projected = offset + coefficient.unsqueeze(-1) * direction
    return alpha * projected + (1.0 - alpha) * x


def _half_squared_distance_reward(x: Tensor, y: Tensor) -> Tensor:
    return 1.0 - 0.5 * (x - y).pow(2).sum(-1)


def _required(value: Tensor | None, name: str, variant: str) -> Tensor:
    if value is None:
        raise ValueError(f"Reward variant {variant!r} needs {name}; got None. Pass {name}=...")
    return value


def liv(heads: RewardHeads | None, s: Tensor, *, g: Tensor, **unused) -> Tensor:
    """Zero-shot reward r^VLM(s_t) = csim(s_t, g) (thesis 4.1; LIV without heads).

    ``heads`` is ignored (may be None).
    """
    return cosine_similarity(s, g)


def furl(heads: RewardHeads, s: Tensor, *, g: Tensor, **unused) -> Tensor:
    """FuRL: r^VLM(s_t) = csim(f_{W_I}(s_t), f_{W_L}(g)) (thesis 3.1.3)."""
    return cosine_similarity(heads.image(s), heads.text(g))


def p1(heads: RewardHeads, s: Tensor, *, s0: Tensor | None = None, g: Tensor,
       b: Tensor, **unused) -> Tensor:
    """P1, delta features before the heads (thesis 4.2.1):
    r_P1(s_t) = csim(f^P_{W_I}(s_t - s_0), f^P_{W_L}(g - b)).
    """
    s0 = _required(s0, "s0", "p1")
    return cosine_similarity(heads.image(s - s0), heads.text(g - b))


def p2(heads: RewardHeads, s: Tensor, *, s0: Tensor | None = None, g: Tensor,
       b: Tensor, **unused) -> Tensor:
    """P2, delta features after the heads (thesis 4.2.1):
    r_P2(s_t) = csim(f^P_{W_I}(s_t) - f^P_{W_I}(s_0), f^P_{W_L}(g) - f^P_{W_L}(b)).

    At t = 0 the image part is the zero vector and the reward is 0.
    """
    s0 = _required(s0, "s0", "p2")
    image = heads.image(s) - heads.image(s0)
    return cosine_similarity(image, heads.text(g) - heads.text(b))


def p3(heads: RewardHeads, s: Tensor, *, g: Tensor, b: Tensor, alpha: float = ALPHA,
       projection: str = PROJECTION, **unused) -> Tensor:
    """P3, goal-baseline regularisation after the heads (thesis 4.2.2)::

        r_P3(s_t) = 1 - 1/2 ||alpha proj_L(f^P_{W_I}(s_t)) + (1 - alpha) f^P_{W_I}(s_t)
                              - f^P_{W_L}(g)||^2,

    L from f^P_{W_L}(g) - f^P_{W_L}(b).

    As in the thesis's release, the head outputs are scaled to unit length first:
    u = f_I(s_t)/||f_I(s_t)||, v_g = f_L(g)/||f_L(g)||, v_b = f_L(b)/||f_L(b)||, and
    r = 1 - 1/2 ||alpha proj_L u + (1 - alpha) u - v_g||^2 with L from v_g - v_b (the regularised
    vector is not renormalised). With alpha = 0 this is FuRL's csim.
    """
    image, goal, baseline = unit(heads.image(s)), unit(heads.text(g)), unit(heads.text(b))
    regularised = goal_baseline_regularise(image, goal, baseline, alpha, projection)
    return _half_squared_distance_reward(regularised, goal)


def p4(heads: RewardHeads, s: Tensor, *, g: Tensor, b: Tensor, alpha: float = ALPHA,
       projection: str = PROJECTION, **unused) -> Tensor:
    """P4, goal-baseline regularisation before the heads (thesis 4.2.2):
    r_P4(s_t) = 1 - 1/2 ||f^P_{W_I}(alpha proj_L s_t + (1 - alpha) s_t) - f^P_{W_L}(g)||^2,
    L = g - b.

    The regularisation runs on the raw embeddings s_t, g and b (``projection="origin"``, as the
    equation and the thesis's release write it). As in the release, both head outputs are then
    scaled to unit length before the distance, so the reward equals
    csim(f_I(alpha proj_L s_t + (1 - alpha) s_t), f_L(g)).
    """
    regularised = goal_baseline_regularise(s, g, b, alpha, projection)
    return _half_squared_distance_reward(unit(heads.image(regularised)), unit(heads.text(g)))


# The built-in positional rewards (liv is zero-shot: no heads).
register_reward("liv", liv, kind="positional", image_input=None)
register_reward("furl", furl, kind="positional", image_input="embedding")
register_reward("p1", p1, kind="positional", image_input="embedding")
register_reward("p2", p2, kind="positional", image_input="embedding")
register_reward("p3", p3, kind="positional", image_input="embedding")
register_reward("p4", p4, kind="positional", image_input="embedding")
