"""The certainty that a direction is beneficial, and d_certainty (beyond the thesis, section 6.4
proposal).

The thesis observes that finetuned D3 behaves like an indicator (its loss only pushes directions up
or down) and proposes a target instead: the certainty t that the observed direction is beneficial,
positive when directions like it are prevalent in positive trajectories at that position,
negative when prevalent in negative ones, near 0 when unsure; trained with (r - t)^2, or used as a
factor on D3's output. The thesis leaves open how t is computed ("some algorithm or a separate
neural network"). Here it is a kernel estimate over labelled reference states (position p_i = s_i,
direction u_i = s_i - s_{i-k}, label +1 or -1), the replay buffer's positives and negatives:

    n+ = sum_{i positive} kappa_i,   n- = sum_{i negative} kappa_i,
    kappa_i = exp(-[(1 - csim(p, p_i)) / m_p + (1 - csim(u, u_i)) / m_u] / beta),
    t(p, u) = (n+ - n-) / (n+ + n- + c).

- The kernel is a product of a position kernel and a direction kernel on the unit sphere (von
  Mises-Fisher shaped): a reference counts when it is near in *both*, "directions like it at that
  position".
- m_p and m_u are the median cosine distances among the references' positions and among their
  directions. Measuring distances in these units makes the bandwidth beta scale-free: LIV's frames
  of one task are far more alike than metaworld_small's (positions), while two directions are
  close to orthogonal for every encoder.
- c is a pseudo-count: with little evidence nearby (n+ + n- << c), t shrinks to 0 ("unsure"); with
  only positives nearby, t -> +1; with only negatives, t -> -1. Positives and negatives are drawn
  in equal numbers by the finetuning sampler, so n+ and n- are on one scale.

Why not a classifier: a network trained to tell positive from negative states extrapolates with
confidence to directions no episode took, where the thesis asks for a target near 0; the kernel
estimate is near 0 there by construction, needs no training of its own, and is computed from the
same batch the heads are trained on.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from temporal_torchrl.defaults import CERTAINTY_BANDWIDTH, CERTAINTY_PRIOR
from temporal_torchrl.rewards.directional import _concatenated
from temporal_torchrl.rewards.heads import RewardHeads
from temporal_torchrl.rewards.positional import EPS, _required, unit
from temporal_torchrl.rewards.registry import register_reward

#: Pairs (i, i + s mod R) for this many shifts s estimate the median distances (see
#: :func:`reference_scales`).
SCALE_SHIFTS = 16


def reference_scales(positions: Tensor, directions: Tensor) -> Tensor:
    """``[m_p, m_u]``: the median cosine distance 1 - csim among distinct pairs of reference
    ``positions [R, D]`` and among their ``directions [R, D]`` (1 with fewer than 2 references,
    floored at EPS for identical ones).

    The ordered distinct pairs are the pairs (i, i + s mod R) over the shifts s = 1 .. R - 1;
    with more than :data:`SCALE_SHIFTS` + 1 references, :data:`SCALE_SHIFTS` shifts spread
    evenly over that range are used, a systematic sample of all pairs (8,192 of the 261,632 of a
    finetuning batch of 512 references) that spares the full distance matrix and its median.
    """
    count = positions.shape[0]
    if count < 2:
        return positions.new_ones(2)
    shifts = torch.linspace(1, count - 1, min(count - 1, SCALE_SHIFTS)).round().long().unique()
    scales = []
    for vectors in (positions, directions):
        unit_vectors = unit(vectors)
        distances = torch.cat([1.0 - (unit_vectors * unit_vectors.roll(-int(shift), 0)).sum(-1)
                               for shift in shifts])
        scales.append(distances.median().clamp_min(EPS))
    return torch.stack(scales)


def direction_certainty(positions: Tensor, directions: Tensor, reference_positions: Tensor,
                        reference_directions: Tensor, reference_labels: Tensor, *,
                        bandwidth: float = CERTAINTY_BANDWIDTH, prior: float = CERTAINTY_PRIOR,
                        scales: Tensor | None = None, exclude: Tensor | None = None) -> Tensor:
    """The certainty t(p, u) in (-1, 1) that the direction ``directions`` at ``positions`` is
    beneficial (module docstring: kernel counts of positive and negative references).

    Args:
        positions, directions: the queries p and u, ``[..., D]`` each.
        reference_positions, reference_directions: p_i and u_i, ``[R, D]``.
        reference_labels: +1 (positive), -1 (negative) or 0 (an empty slot, ignored), ``[R]``.
        bandwidth: beta (> 0), in units of the references' median distances.
        prior: the pseudo-count c (> 0).
        scales: ``[m_p, m_u]``; default :func:`reference_scales` of the references.
        exclude: boolean ``[Q, R]`` (Q the number of queries), True where a reference must not
            count for a query: the query itself, when the queries are the references
            (leave-one-out, so a state is not its own evidence).

    Returns:
        t, shape ``positions.shape[:-1]``, without gradient.
    """
    if not bandwidth > 0 or not prior > 0:
        raise ValueError(f"bandwidth={bandwidth!r}, prior={prior!r}; expected both > 0.")
    batch = positions.shape[:-1]
    with torch.no_grad():
        if reference_labels.numel() == 0:
            return positions.new_zeros(batch)
        if scales is None:
            scales = reference_scales(reference_positions, reference_directions)
        query_positions = unit(positions.reshape(-1, positions.shape[-1]))
        query_directions = unit(directions.reshape(-1, directions.shape[-1]))
        position_distance = 1.0 - query_positions @ unit(reference_positions).T
        direction_distance = 1.0 - query_directions @ unit(reference_directions).T
        weights = torch.exp(-(position_distance / scales[0] + direction_distance / scales[1])
                            / bandwidth)
        if exclude is not None:
            weights = weights.masked_fill(exclude, 0.0)
        labels = reference_labels.to(weights.dtype)
        positive = weights @ (labels > 0).to(weights.dtype)
        negative = weights @ (labels < 0).to(weights.dtype)
        return ((positive - negative) / (positive + negative + prior)).reshape(batch)


class CertaintyMemory(nn.Module):
    """Reference states for the certainty at reward time (the multiplicative option,
    ``TemporalReward(certainty_scaling=True)``: r_D <- ``|t(s_t, Δs_t)|`` r_D).

    Holds the positions, directions and labels of the last finetuning batch
    (:meth:`remember`, called by the directional losses) and their :func:`reference_scales`, as
    buffers: they are part of the reward's ``state_dict``, so a resumed run scores with the
    references it had. Empty until the first update, when the certainty is 0 everywhere.

    Args:
        embedding_dim: D.
        bandwidth, prior: as :func:`direction_certainty`.
    """

    def __init__(self, embedding_dim: int, bandwidth: float = CERTAINTY_BANDWIDTH,
                 prior: float = CERTAINTY_PRIOR):
        super().__init__()
        if not bandwidth > 0 or not prior > 0:
            raise ValueError(f"CertaintyMemory: bandwidth={bandwidth!r}, prior={prior!r}; "
                             "expected both > 0.")
        self.bandwidth = float(bandwidth)
        self.prior = float(prior)
        self.register_buffer("positions", torch.zeros(0, embedding_dim))
        self.register_buffer("directions", torch.zeros(0, embedding_dim))
        self.register_buffer("labels", torch.zeros(0))
        self.register_buffer("scales", torch.ones(2))

    @torch.no_grad()
    def remember(self, positions: Tensor, directions: Tensor, labels: Tensor) -> None:
        """Replace the references by ``positions``, ``directions`` ``[R, D]`` and ``labels``
        ``[R]`` (+1 positive, -1 negative)."""
        self.positions = positions.detach().float().clone()
        self.directions = directions.detach().float().clone()
        self.labels = labels.detach().float().clone()
        self.scales = reference_scales(self.positions, self.directions)

    def forward(self, position: Tensor, direction: Tensor) -> Tensor:
        """t(s_t, Δs_t) against the remembered references, shape ``position.shape[:-1]``."""
        return direction_certainty(position, direction, self.positions, self.directions,
                                   self.labels, bandwidth=self.bandwidth, prior=self.prior,
                                   scales=self.scales)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        # The number of references is the saved batch's, not the fresh module's (zero).
        for name in ("positions", "directions", "labels"):
            if prefix + name in state_dict:
                setattr(self, name, torch.empty_like(state_dict[prefix + name]))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def extra_repr(self) -> str:
        return (f"references={self.labels.numel()}, bandwidth={self.bandwidth}, "
                f"prior={self.prior}")


def d_certainty(heads: RewardHeads, s: Tensor, *, s_prev: Tensor | None = None, g: Tensor,
                b: Tensor, position: Tensor | None = None, **unused) -> Tensor:
    """d_certainty, the certainty-shaped directional reward (beyond the thesis, section 6.4
    proposal):
    r(s_t, Δs_t) = csim(f^D_{W_I}(n(s_t) ⊕ n(Δs_t)), f^D_{W_L}(g - b)),
    D3's equation, registered with the ``"certainty"`` objective: its heads are trained towards
    the certainty t(s_t, Δs_t) with (r - t)^2
    (:class:`~temporal_torchrl.objectives.CertaintyLoss`) instead of D3's loss, so the reward
    takes graded values, near 0 where the batch holds no evidence. The position s_t is
    ``position`` (default ``s``).
    """
    s_prev = _required(s_prev, "s_prev", "d_certainty")
    position = s if position is None else position
    return _concatenated(heads, position, s - s_prev, g, b)


# The certainty objective gives d_certainty its options certainty_bandwidth and certainty_prior
# (registry.CERTAINTY_OPTIONS), set with reward.options like any reward's.
register_reward("d_certainty", d_certainty, kind="directional", image_input="concatenated",
                objective="certainty")
