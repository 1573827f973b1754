"""Directional VLM rewards r_D (thesis 4.3): the value of the direction Δs_t = s_t - s_{t-k}.

Same registry signature as :mod:`temporal_torchrl.rewards.positional`:
``fn(heads, s, *, s0, s_prev, g, b, alpha, position=None, projection="origin") -> reward``.
The direction is always ``s - s_prev``; D3-D5 also read a position part computed from
``position`` (default ``s``). Passing the position separately lets the directional loss
(thesis 4.3.3) score any direction at a fixed position:

- observed direction: ``fn(heads, s_t, s_prev=s_{t-k})``
- towards the goal:   ``fn(heads, s_g, s_prev=s_t, position=s_t)``
- opposite direction: ``fn(heads, s_{t-k}, s_prev=s_t, position=s_t)``

Beyond the thesis (section 6.3 proposal), :func:`d_sequence` reads the window of the last K
embeddings s_{t-K+1} .. s_t (``window``) instead of one direction: the sequence of its K - 1 steps,
each at the position, through a small sequence encoder. Its counterparts of the directional loss's
directions are whole paths: :func:`straight_window` towards the goal, the window reversed for the
opposite direction. Called with ``window=None`` it scores the straight path from ``s_prev`` to
``s`` without building it (see :func:`d_sequence`).

Zero directions: at the start of an episode s_{t-k} = s_0 = s_t, so Δs_t = 0. Every normalisation
divides by max(||x||, eps) (:data:`~temporal_torchrl.rewards.positional.EPS`), which maps the zero
vector to zero: D1 and D3-D5 then feed the head a zero direction part (finite output), and D2's
zero image difference gives a reward of 0.
"""

from __future__ import annotations

import torch
from torch import Tensor

from temporal_torchrl.defaults import ALPHA, PROJECTION
from temporal_torchrl.rewards.heads import RewardHeads
from temporal_torchrl.rewards.positional import (
    _required,
    clamped_norm,
    cosine_similarity,
    goal_baseline_regularise,
    unit,
)
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
       alpha: float = ALPHA, position: Tensor | None = None, projection: str = PROJECTION,
       **unused) -> Tensor:
    """D5, goal-baseline-regularised position and direction (thesis 4.3.2)::

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


def window_tokens(window: Tensor, position: Tensor | None = None) -> Tensor:
    """The tokens of d_sequence's image head: x_j = n(p) ⊕ n(w_j - w_{j-1}), j = 1 .. K - 1.

    ``window [..., K, D]`` holds w_0 .. w_{K-1} (oldest first); ``position`` p (``[..., D]``,
    default the newest entry w_{K-1}) broadcasts over the window. Returns ``[..., K - 1, 2 D]``:
    each step of the window as D3's image input, read at one position. Zero steps (the padding
    with s_0 at an episode start) stay zero after :func:`unit`.
    """
    position, steps = _window_steps(window, position)
    position_part, steps = torch.broadcast_tensors(unit(position).unsqueeze(-2), unit(steps))
    return torch.cat((position_part, steps), dim=-1)


def _window_steps(window: Tensor, position: Tensor | None) -> tuple[Tensor, Tensor]:
    """The position p ``[..., D]`` (default the window's newest entry) and the steps
    w_j - w_{j-1} ``[..., K - 1, D]`` of a window, before :func:`window_tokens` normalises
    them."""
    if window.ndim < 2 or window.shape[-2] < 2:
        raise ValueError(f"window of shape {tuple(window.shape)}; expected [..., K, D] with "
                         "K >= 2 embeddings (K - 1 steps).")
    position = window[..., -1, :] if position is None else position
    return position, window[..., 1:, :] - window[..., :-1, :]


def straight_window(start: Tensor, end: Tensor, length: int) -> Tensor:
    """The window of ``length`` embeddings moving in equal steps from ``start`` to ``end``:
    w_j = start + j/(K - 1) (end - start), shape ``[..., K, D]`` (inputs broadcast).

    Every step of it is (end - start)/(K - 1), so at the position ``start`` d_sequence reads the
    direction end - start in every token: the window counterpart of the directional loss's
    direction towards the goal, s_g - s_t.
    """
    if isinstance(length, bool) or not isinstance(length, int) or length < 2:
        raise ValueError(f"length={length!r}; expected an integer >= 2 (a window of K >= 2 "
                         "embeddings).")
    start, end = torch.broadcast_tensors(start, end)
    fractions = torch.linspace(0.0, 1.0, length, dtype=start.dtype, device=start.device)
    return start.unsqueeze(-2) + fractions.unsqueeze(-1) * (end - start).unsqueeze(-2)


def d_sequence(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None,
               window: Tensor | None = None, g: Tensor, b: Tensor,
               position: Tensor | None = None, **unused) -> Tensor:
    """d_sequence, the short-horizon sequence directional reward (beyond the thesis, section
    6.3 proposal):
    r(s_t, W_t) = csim(f^D_{W_I}(x_1 .. x_{K-1}), f^D_{W_L}(g - b)),
    x_j = n(s_t) ⊕ n(w_j - w_{j-1}),  W_t = (w_0 .. w_{K-1}) = (s_{t-K+1} .. s_t),
    with f^D_{W_I} a :class:`~temporal_torchrl.rewards.heads.SequenceEncoder` over the K - 1
    tokens (:func:`window_tokens`): every step of the recent past at the current position, in
    order. The position s_t is ``position`` (default the newest embedding of the window).

    With K = 2 the single token n(s_t) ⊕ n(s_t - s_{t-1}) is D3's image input with k = 1, so
    d_sequence is D3 whose one k-step direction is replaced by the ordered sequence of steps.
    ``s`` and ``s_prev`` are not read when a window is given: the window carries the direction.

    ``window=None`` scores the straight path from ``s_prev`` to ``s``, the window
    ``straight_window(s_prev, s, K)`` whose every step is along s - s_prev (the directional
    loss's path towards the goal), without building it: its K - 1 tokens are one token
    n(p) ⊕ n(s - s_prev), which the sequence encoder embeds once. The position p defaults to
    ``s``, that window's newest entry.
    """
    if window is None:
        s_prev = _required(s_prev, "window (or s_prev, for the straight path)", "d_sequence")
        position = s if position is None else position
        step = (s - s_prev).unsqueeze(-2)
        # One step's norm, broadcast with it: the encoder embeds the step once (stride 0).
        steps, norms = (x.expand(*x.shape[:-2], heads.image.length, x.shape[-1])
                        for x in (step, clamped_norm(step)))
    else:
        position, steps = _window_steps(window, position)
        norms = clamped_norm(steps)
    # heads.image(window_tokens(window, position)): n(s_t) embedded once per window, and each
    # step's normalisation applied to its embedding (see SequenceEncoder.forward_with_context)
    image = heads.image.forward_with_context(unit(position), steps, norms)
    return cosine_similarity(image, heads.text(g - b))


# The built-in directional rewards; d3-d5 read position ⊕ direction (2·D),
# d_sequence a window of K embeddings (K - 1 tokens of 2·D); its layout gives it the option
# window, K (registry.WINDOW_OPTIONS), set with reward.options like any reward's.
register_reward("d1", d1, kind="directional", image_input="embedding")
register_reward("d2", d2, kind="directional", image_input="embedding")
register_reward("d3", d3, kind="directional", image_input="concatenated")
register_reward("d4", d4, kind="directional", image_input="concatenated")
register_reward("d5", d5, kind="directional", image_input="concatenated")
register_reward("d_sequence", d_sequence, kind="directional", image_input="window")
