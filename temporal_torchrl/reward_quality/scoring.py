"""Score one reward on held-out episodes: the rewards a training run would give, and their metrics.

A reward is scored at the states the env rewards, s_1 .. s_T of an episode (s_0 is the reset
frame, which no step is rewarded for), with s_0 the episode's first embedding and s_{t-k} the one
k steps back, clamped to s_0, exactly as the history transform and the replay buffer provide them.
A successful episode is read up to its first success state s_L (L = first successful step + 1):
what comes after is not progress any more.

- positional rewards: value-order correlation along each successful episode (s_1 .. s_L; mean and
  spread over episodes) and AUROC of the per-step reward, successful-episode steps (s_1 .. s_L)
  against failed-episode steps (s_1 .. s_T);
- directional rewards: direction accuracy on successful episodes and AUROC as above. The
  episode s_0 .. s_L played backwards is u_j = s_{L-j}: at frame s_t it has the previous frame
  s_{t+k} (clamped to s_L) and the first frame s_L. The forward and backward rewards are compared
  at the frames s_1 .. s_{L-1}, where both directions are rewarded steps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from torch import Tensor

from temporal_torchrl.data import episode_history
from temporal_torchrl.envs import first_success_index
from temporal_torchrl.reward_quality.metrics import (
    auroc,
    direction_accuracy,
    value_order_correlation,
)
from temporal_torchrl.rewards import TemporalReward

POSITIONAL_KIND = "positional"
DIRECTIONAL_KIND = "directional"


def episode_embeddings(episode: TensorDictBase) -> Tensor:
    """The embeddings s_0 .. s_T of an episode in ``env.rollout()`` layout: float32 ``[T+1, D]``."""
    if "embedding" not in episode.keys() or ("next", "embedding") not in episode.keys(True):
        raise ValueError("the episode carries no 'embedding' and ('next', 'embedding'); embed it "
                         "first (temporal_torchrl.data.embed_episode).")
    return torch.cat([episode["embedding"][:1], episode["next", "embedding"]]).float()


def reward_kind(reward: TemporalReward) -> str:
    """``"positional"`` or ``"directional"``: the one part a scored reward must have."""
    if (reward.positional is None) == (reward.directional is None):
        raise ValueError(
            f"a scored reward has exactly one part; got positional={reward.positional!r}, "
            f"directional={reward.directional!r}. Build one TemporalReward per variant "
            "(reward_from_config(config, g, b, variant=...)).")
    return POSITIONAL_KIND if reward.positional is not None else DIRECTIONAL_KIND


@torch.no_grad()
def state_rewards(reward: TemporalReward, states: Tensor) -> Tensor:
    """The reward of every state of one episode ``states`` [N, D] (s_0 first): ``[N]``.

    Each state gets the history the env gives it: s_0, s_{t-k} (clamped to s_0) and, for a
    reward that reads a window, the last ``reward.window_length`` states (padded with s_0).
    Index 0 is the reset frame's value (zero direction for a directional reward); the env
    rewards indices 1 .. N-1.
    """
    history = episode_history(states, reward.k, reward.window_length)
    first, previous, window = history["initial"], history["previous"], history["window"]
    if reward_kind(reward) == POSITIONAL_KIND:
        return reward.positional_reward(states, first, previous, window=window)
    return reward.directional_reward(states, previous, first, window=window)


def reward_curve(reward: TemporalReward, episode: TensorDictBase) -> Tensor:
    """The rewards r_1 .. r_T a training run gives along ``episode``: ``[T]``."""
    return state_rewards(reward, episode_embeddings(episode))[1:]


def success_length(episode: TensorDictBase) -> int:
    """L, the index of the first success state s_L of a successful episode."""
    return first_success_index(episode) + 1


def backward_rewards(reward: TemporalReward, states: Tensor) -> Tensor:
    """The rewards of ``states`` [N, D] with the episode played backwards, at the same frames."""
    return state_rewards(reward, states.flip(0)).flip(0)


@dataclass(frozen=True)
class RewardScores:
    """The metrics of one reward on held-out episodes (None where they do not apply).

    Attributes:
        kind: ``"positional"`` or ``"directional"``.
        auroc: successful-episode steps against failed-episode steps.
        value_order_correlation, value_order_correlation_std: mean and standard deviation over
            the successful episodes (positional rewards).
        direction_accuracy: pooled over the successful episodes' steps (directional rewards).
        positive_steps, negative_steps: the number of steps of each side of the AUROC.
    """

    kind: str
    auroc: float
    positive_steps: int
    negative_steps: int
    value_order_correlation: float | None = None
    value_order_correlation_std: float | None = None
    direction_accuracy: float | None = None


def score_reward(reward: TemporalReward, successful: Sequence[TensorDictBase],
                 failed: Sequence[TensorDictBase]) -> RewardScores:
    """Score ``reward`` (one positional or one directional part) on held-out episodes.

    Args:
        reward: the reward to score, heads as they are.
        successful: embedded episodes that reach success.
        failed: embedded episodes that never do.
    """
    if not successful or not failed:
        raise ValueError(f"scoring needs successful and failed episodes; got {len(successful)} "
                         f"and {len(failed)}. Hold out episodes of both kinds.")
    kind = reward_kind(reward)
    positive_values, negative_values, correlations, forward, backward = [], [], [], [], []
    for episode in successful:
        length = success_length(episode)
        states = episode_embeddings(episode)[:length + 1]
        rewards = state_rewards(reward, states)
        positive_values.append(rewards[1:])
        if kind == POSITIONAL_KIND and length >= 2:
            correlations.append(value_order_correlation(rewards[1:]))
        if kind == DIRECTIONAL_KIND and length >= 2:
            forward.append(rewards[1:length])
            backward.append(backward_rewards(reward, states)[1:length])
    for episode in failed:
        if bool(episode["next", "success"].any()):
            raise ValueError("a 'failed' episode reaches success; pass only episodes that never "
                             "succeed as failed.")
        negative_values.append(reward_curve(reward, episode))
    positive, negative = torch.cat(positive_values), torch.cat(negative_values)
    scores = {"kind": kind, "auroc": auroc(positive, negative),
              "positive_steps": positive.numel(), "negative_steps": negative.numel()}
    if kind == POSITIONAL_KIND:
        if not correlations:
            raise ValueError("every successful episode succeeds at its first step; a value-order "
                             "correlation needs at least two steps before the success.")
        values = torch.tensor(correlations, dtype=torch.float64)
        scores["value_order_correlation"] = float(values.mean())
        scores["value_order_correlation_std"] = float(values.std(unbiased=False))
    else:
        if not forward:
            raise ValueError("every successful episode succeeds within its first step; direction "
                             "accuracy needs at least two steps before the success.")
        scores["direction_accuracy"] = direction_accuracy(torch.cat(forward), torch.cat(backward))
    return RewardScores(**scores)
