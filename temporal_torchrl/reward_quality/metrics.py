"""Offline reward-quality metrics: value-order correlation, AUROC and direction accuracy.

Each metric reads rewards a reward function gave to stored states, so a reward can be screened
before any RL run:

- :func:`value_order_correlation` (VOC): the Spearman rank correlation between time and the
  reward along one successful episode (Ma et al. 2024, "Vision Language Models are In-Context
  Value Learners"): 1 when the reward rises at every step, -1 when it falls at every step.
- :func:`auroc`: the probability that a step of a successful episode gets a higher reward than a
  step of a failed episode (ties count one half): 1 for a perfect separator, 0.5 for chance.
- :func:`direction_accuracy`: the fraction of steps at which a directional reward values the
  frames in their real order above the same frames played backwards (ties count one half): 1
  for a reward that reads the direction of time, 0.5 for one that ignores it.

Ranks are average ranks (tied values share the mean of their positions), as in
``scipy.stats.rankdata``; everything is computed in float64.
"""

from __future__ import annotations

import torch
from torch import Tensor


def _as_scores(values: Tensor, name: str, minimum: int = 1) -> Tensor:
    values = torch.as_tensor(values)
    if values.ndim != 1:
        raise ValueError(f"{name} has shape {tuple(values.shape)}; expected one dimension "
                         "(one reward per step).")
    if values.numel() < minimum:
        raise ValueError(f"{name} has {values.numel()} values; expected at least {minimum}.")
    values = values.detach().to(torch.float64).cpu()
    if not bool(torch.isfinite(values).all()):
        raise ValueError(f"{name} holds NaN or infinite rewards; a reward must be finite at "
                         "every step (check the reward function for divisions by zero).")
    return values


def average_ranks(values: Tensor) -> Tensor:
    """1-based ranks of a 1-D tensor, tied values sharing the mean of their ranks (float64).

    >>> average_ranks(torch.tensor([10.0, 30.0, 20.0, 20.0])).tolist()
    [1.0, 4.0, 2.5, 2.5]
    """
    values = _as_scores(values, "values")
    order = torch.argsort(values, stable=True)
    _, group, counts = torch.unique_consecutive(values[order], return_inverse=True,
                                                return_counts=True)
    last = torch.cumsum(counts, 0).to(torch.float64)
    mean_rank = last - (counts.to(torch.float64) - 1.0) / 2.0
    ranks = torch.empty_like(values)
    ranks[order] = mean_rank[group]
    return ranks


def spearman_correlation(x: Tensor, y: Tensor) -> float:
    """Spearman's rank correlation of two 1-D tensors of equal length.

    Defined as 0.0 when either side is constant: a constant reward says nothing about order
    (the textbook formula divides by zero there).

    >>> round(spearman_correlation(torch.tensor([1.0, 2.0, 3.0]), torch.tensor([1.0, 9.0, 4.0])), 6)
    0.5
    """
    x, y = _as_scores(x, "x", 2), _as_scores(y, "y", 2)
    if x.shape != y.shape:
        raise ValueError(f"x has {x.numel()} values and y {y.numel()}; a rank correlation "
                         "pairs them one to one.")
    rank_x, rank_y = average_ranks(x), average_ranks(y)
    rank_x, rank_y = rank_x - rank_x.mean(), rank_y - rank_y.mean()
    scale = rank_x.norm() * rank_y.norm()
    if scale == 0:
        return 0.0
    return float((rank_x @ rank_y) / scale)


def value_order_correlation(rewards: Tensor) -> float:
    """VOC: Spearman correlation between the step index and the reward along one episode.

    ``rewards`` ``[T]`` are the rewards at consecutive steps of one successful episode (up to
    its first success). 1.0 for a reward that rises with time, -1.0 for one that falls, 0.0 for
    a constant one.

    >>> value_order_correlation(torch.tensor([0.1, 0.2, 0.2, 0.5]))
    0.9486832980505138
    """
    rewards = _as_scores(rewards, "rewards", 2)
    return spearman_correlation(torch.arange(rewards.numel(), dtype=torch.float64), rewards)


def auroc(positive_scores: Tensor, negative_scores: Tensor) -> float:
    """Area under the ROC curve of scores that should be higher for positives than negatives.

    Computed exactly as the Mann-Whitney statistic, P(positive > negative) + P(tie) / 2 over all
    pairs: 1.0 for a perfect separator, 0.5 for chance, 0.0 for a perfectly inverted one.

    >>> auroc(torch.tensor([0.9, 0.8]), torch.tensor([0.1, 0.85]))
    0.75
    """
    positive = _as_scores(positive_scores, "positive_scores")
    negative = _as_scores(negative_scores, "negative_scores")
    ranks = average_ranks(torch.cat([positive, negative]))
    count_positive, count_negative = positive.numel(), negative.numel()
    wins = ranks[:count_positive].sum() - count_positive * (count_positive + 1) / 2
    return float(wins / (count_positive * count_negative))


def direction_accuracy(forward_rewards: Tensor, backward_rewards: Tensor) -> float:
    """Fraction of steps where the reward of the real order beats the reversed order.

    ``forward_rewards[i]`` and ``backward_rewards[i]`` are a directional reward at the same frame,
    once with the episode played forwards and once backwards. Exact ties count one half, so a
    reward that ignores the order (identical values) scores 0.5.

    >>> direction_accuracy(torch.tensor([1.0, 0.5, 0.0]), torch.tensor([0.0, 0.5, 1.0]))
    0.5
    """
    forward = _as_scores(forward_rewards, "forward_rewards")
    backward = _as_scores(backward_rewards, "backward_rewards")
    if forward.shape != backward.shape:
        raise ValueError(f"forward_rewards has {forward.numel()} values and backward_rewards "
                         f"{backward.numel()}; they must score the same frames.")
    wins = (forward > backward).to(torch.float64) + 0.5 * (forward == backward).to(torch.float64)
    return float(wins.mean())
