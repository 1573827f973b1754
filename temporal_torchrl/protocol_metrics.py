"""Evaluation metrics of the thesis's two protocols (section 5.1).

Episodes are numbered from 1, as in the thesis: ``z_1`` is the success of the first training
episode. A Python sequence ``successes`` holds ``z_1, z_2, ...`` at positions ``0, 1, ...``, so
the metrics below return 1-based episode numbers (``ttfs([False, True]) == 2``).

- Stage 1: Time To First Success ``TTFS = min{i | z_i = 1}`` and Time To 50 Successes
  ``TT50S = min{i | sum_{j<=i} z_j = 50}``; when that never happens within the horizon (1,000
  episodes in the thesis) the metric equals the horizon.
- Stage 2: Running Average Success ``RAS(e; w) = (1/w) sum_{i=e-w+1}^{e} z_i`` with the task's
  episode budget ``e`` and window ``w = 150``.

An episode is a success when the task's success flag was set at any of its steps
(:func:`episode_success`).

Example:
    >>> ttfs([False, False, True])
    3
    >>> tt50s([True] * 10, count=3)
    3
    >>> ras([False] * 50 + [True] * 150, budget=200)
    1.0
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

#: The thesis's horizon for stage-1 runs (episodes): TTFS and TT50S never exceed it.
DEFAULT_HORIZON = 1000
#: The thesis's RAS window w (episodes).
DEFAULT_WINDOW = 150


def episode_success(success: torch.Tensor | Sequence[bool]) -> bool:
    """``z_i``: whether the success flag was set at any step of one episode."""
    return bool(torch.as_tensor(success).bool().any())


def _as_bools(successes: Sequence[bool] | torch.Tensor) -> list[bool]:
    if isinstance(successes, torch.Tensor):
        return [bool(z) for z in successes.reshape(-1).tolist()]
    return [bool(z) for z in successes]


def time_to_successes(successes: Sequence[bool] | torch.Tensor, count: int,
                      horizon: int = DEFAULT_HORIZON) -> int:
    """1-based episode at which the ``count``-th success happened, ``horizon`` if never.

    Only the first ``horizon`` episodes are looked at, so the result is at most ``horizon``.
    """
    if count < 1:
        raise ValueError(f"count={count} must be >= 1 (number of successes to wait for).")
    if horizon < 1:
        raise ValueError(f"horizon={horizon} must be >= 1 (episodes).")
    total = 0
    for episode, success in enumerate(_as_bools(successes)[:horizon], start=1):
        total += success
        if total == count:
            return episode
    return horizon


def ttfs(successes: Sequence[bool] | torch.Tensor, horizon: int = DEFAULT_HORIZON) -> int:
    """Time To First Success (thesis section 5.1): ``min{i | z_i = 1}``, 1-based, capped."""
    return time_to_successes(successes, 1, horizon)


def tt50s(successes: Sequence[bool] | torch.Tensor, horizon: int = DEFAULT_HORIZON,
          count: int = 50) -> int:
    """Time To 50 Successes (thesis section 5.1): ``min{i | sum_{j<=i} z_j = 50}``, capped."""
    return time_to_successes(successes, count, horizon)


def ras(successes: Sequence[bool] | torch.Tensor, budget: int,
        window: int = DEFAULT_WINDOW) -> float | None:
    """Running Average Success ``RAS(e; w)`` (thesis section 5.1) of episodes ``e-w+1..e``.

    Returns ``None`` when fewer than ``budget`` episodes were run: the metric is undefined then
    (a run that stopped early is not scored as if it had failed the missing episodes).
    Raises ``ValueError`` when the window does not fit in the budget.
    """
    if window < 1:
        raise ValueError(f"window={window} must be >= 1 (episodes).")
    if budget < window:
        raise ValueError(f"budget={budget} must be >= window={window}: RAS averages the "
                         "episodes budget-window+1..budget.")
    values = _as_bools(successes)
    if len(values) < budget:
        return None
    return sum(values[budget - window:budget]) / window
