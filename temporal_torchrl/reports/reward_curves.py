"""r_P and r_D along stored episodes, computed with a run's saved reward heads (Figure 5.12).

A run directory keeps its reward (``checkpoint.pt``: ``"reward"``, the
:class:`~temporal_torchrl.rewards.TemporalReward` state with the goal and baseline text
embeddings and the heads as they were at the last checkpoint) and every inserted episode
(``replay/NNNNNN.pt``, in insertion order, the first ``"preloaded"`` ones the expert episodes).
The reward is rebuilt from ``config.json`` and that state, and scores each state s_t of an
episode with the history the env gives it: s_0 the episode's first state and s_{t-k} the state k
steps back (s_0 while t < k).

Example:
    >>> positive, negative = reward_curves("runs/door-open/.../seed0")  # doctest: +SKIP
    >>> positive.kind, positive.positional[:3]                          # doctest: +SKIP
    ('expert', array([0.12, 0.13, 0.15], dtype=float32))
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from temporal_torchrl.data import NEGATIVE, episode_history
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.runs.readers import load_episode, load_reward

EXPERT = "expert"
SUCCESSFUL = "successful training episode"
FAILED = "failed training episode"


@dataclass(frozen=True)
class EpisodeRewards:
    """The rewards of one stored episode at its states s_1 .. s_T (the rewards its
    transitions received).

    Attributes:
        index: the episode's position in ``replay/`` (insertion order).
        kind: :data:`EXPERT`, :data:`SUCCESSFUL` or :data:`FAILED`.
        steps: ``1 .. T``.
        positional, directional: r_P and r_D at those steps (None for an absent part).
        first_success: the first step with the success flag set, or None.
    """

    index: int
    kind: str
    steps: np.ndarray
    positional: np.ndarray | None
    directional: np.ndarray | None
    first_success: int | None


def episode_rewards(reward: TemporalReward,
                    embeddings: torch.Tensor) -> tuple[np.ndarray | None, np.ndarray | None]:
    """r_P and r_D (None for an absent part) at every state of one episode's embeddings
    ``[T + 1, D]`` (state 0 included), through the reward's own forward as the env computes
    them: s_0, s_{t-k} and (for a sequence reward) the window of the last K embeddings, never
    before state 0; r_D with its certainty scaling when the reward has one."""
    embeddings = embeddings.float()
    history = episode_history(embeddings, reward.k, reward.window_length)
    success = torch.zeros(embeddings.shape[0], 1, dtype=torch.bool)
    with torch.no_grad():
        parts = reward(embeddings, history["initial"], history["previous"], success,
                       window=history["window"])
    positional = (parts["positional_reward"].squeeze(-1).numpy()
                  if reward.positional is not None else None)
    directional = (parts["directional_reward"].squeeze(-1).numpy()
                   if reward.directional is not None else None)
    return positional, directional


def episode_kind(episode: dict[str, torch.Tensor], index: int, preloaded: int) -> str | None:
    """:data:`EXPERT` (preloaded), :data:`SUCCESSFUL`, :data:`FAILED` (every labelled state
    negative), or None (a training episode neither: not possible with the recipe's labels)."""
    if index < preloaded:
        return EXPERT
    if bool(episode["success"][1:].any()):
        return SUCCESSFUL
    if bool((episode["label"][1:] == NEGATIVE).all()):
        return FAILED
    return None


def _rewards(reward: TemporalReward, episode: dict[str, torch.Tensor], index: int,
             kind: str) -> EpisodeRewards:
    positional, directional = episode_rewards(reward, episode["embedding"])
    success = torch.nonzero(episode["success"].reshape(-1)[1:]).reshape(-1)
    return EpisodeRewards(
        index, kind, np.arange(1, episode["embedding"].shape[0]),
        positional[1:] if positional is not None else None,
        directional[1:] if directional is not None else None,
        int(success[0]) + 1 if success.numel() else None)


def reward_curves(run_dir: str | Path, positive: int | None = None,
                  negative: int | None = None) -> tuple[EpisodeRewards, EpisodeRewards]:
    """r_P and r_D along one positive and one negative episode of the run, with its saved heads.

    ``positive`` / ``negative`` are replay indices; by default the first expert episode (else
    the last successful training episode) and the last failed training episode before the
    checkpoint. Raises ``ValueError`` when the run has no such episode, or when a given index is
    not of its kind.
    """
    reward, checkpoint = load_reward(run_dir)
    preloaded, inserted = checkpoint.preloaded, checkpoint.inserted
    wanted = {"positive": (positive, (EXPERT, SUCCESSFUL)), "negative": (negative, (FAILED,))}
    chosen = []
    for role, (index, kinds) in wanted.items():
        if index is not None:
            if not 0 <= index < inserted:
                raise ValueError(f"{role} episode {index} is not in {run_dir}'s replay "
                                 f"(0..{inserted - 1} at its checkpoint).")
            episode = load_episode(run_dir, index)
            kind = episode_kind(episode, index, preloaded)
            if kind not in kinds:
                raise ValueError(f"replay episode {index} of {run_dir} is a {kind}, not a "
                                 f"{role} episode ({' or '.join(kinds)}).")
            chosen.append(_rewards(reward, episode, index, kind))
            continue
        order = (range(preloaded) if role == "positive" and preloaded else
                 range(inserted - 1, preloaded - 1, -1))
        for candidate in order:
            episode = load_episode(run_dir, candidate)
            kind = episode_kind(episode, candidate, preloaded)
            if kind in kinds:
                chosen.append(_rewards(reward, episode, candidate, kind))
                break
        else:
            raise ValueError(f"{run_dir} has no {role} episode ({' or '.join(kinds)}) among its "
                             f"{inserted} stored episodes.")
    return chosen[0], chosen[1]
