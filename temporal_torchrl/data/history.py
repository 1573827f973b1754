"""The per-episode history arithmetic: which rows hold s_0, s_{t-k} and the window of a state.

Inside one episode stored from row ``r_0`` on (state ``t`` at row ``r_0 + t``):

- ``s_0``       = row ``r - step``
- ``s_{t-k}``   = row ``r - min(step, k)`` (clamped to ``s_0`` at the episode start, as the
  history transform does during collection)
- the window ``s_{t-K+1} .. s_t`` (``window_length=K``) = rows ``r - min(step, K - 1 - j)``,
  ``j = 0 .. K - 1`` (padded with ``s_0`` likewise)

The replay's samplers index its storage with these rows; :func:`episode_history` applies them to
one episode's states at once (reward-quality scoring, the reports' reward curves, tests).
"""

from __future__ import annotations

import torch
from torch import Tensor

from temporal_torchrl.rewards.temporal import check_window_length


def _window_rows(rows: torch.Tensor, step: torch.Tensor, window_length: int) -> torch.Tensor:
    """Rows ``rows - min(step, K - 1 - j)``, j = 0 .. K - 1: the window ending at each row,
    never before its episode's first row (``[..., K]``)."""
    offsets = torch.arange(window_length - 1, -1, -1, device=rows.device)
    return rows.unsqueeze(-1) - torch.minimum(offsets, step.unsqueeze(-1))


def state_index(rows: torch.Tensor, step: torch.Tensor, k: int,
                window_length: int | None = None) -> torch.Tensor:
    """The rows a state needs, ``[..., 3 (+ K)]``: ``[s_t, s_0, s_{t-k}, window...]``."""
    rows, step = rows.long(), step.long()
    columns = [rows, rows - step, rows - torch.clamp(step, max=k)]
    index = torch.stack(columns, -1)
    if window_length:
        index = torch.cat([index, _window_rows(rows, step, window_length)], -1)
    return index


def transition_index(rows: torch.Tensor, step: torch.Tensor, k: int,
                     window_length: int | None = None) -> torch.Tensor:
    """The rows a transition from state ``t`` needs, ``[..., 4 (+ K)]``:
    ``[t, t + 1, s_0, s_{t+1-k}, window of s_{t+1}...]``."""
    rows, step = rows.long(), step.long()
    following = rows + 1
    columns = [rows, following, rows - step, following - torch.clamp(step + 1, max=k)]
    index = torch.stack(columns, -1)
    if window_length:
        index = torch.cat([index, _window_rows(following, step + 1, window_length)], -1)
    return index


def episode_history(states: Tensor, k: int, window_length: int | None = None
                    ) -> dict[str, Tensor | None]:
    """The history of every state of one episode ``states [N, ...]`` (s_0 first), as the env's
    history transform gives it during collection: ``initial`` (s_0), ``previous`` (s_{t-k}) and
    ``window`` (the last ``window_length`` states, ``[N, K, ...]``; None without one).

    >>> history = episode_history(torch.arange(5.0).unsqueeze(-1), k=2, window_length=3)
    >>> history["previous"].squeeze(-1).tolist(), history["window"][1].squeeze(-1).tolist()
    ([0.0, 0.0, 0.0, 1.0, 2.0], [0.0, 0.0, 1.0])
    """
    check_window_length(window_length, optional=True)
    steps = torch.arange(states.shape[0], device=states.device)
    index = state_index(steps, steps, k, window_length)
    return {"initial": states[index[:, 1]], "previous": states[index[:, 2]],
            "window": states[index[:, 3:]] if window_length else None}
