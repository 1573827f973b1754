"""Offline finetuning of a reward's heads with the package's own losses and replay buffer.

The training episodes go into an :class:`~temporal_torchrl.data.EpisodeReplayBuffer`, labelled
by the training run's rule, and a :class:`~temporal_torchrl.training.RewardHeadTrainer` on its
finetuning view takes the updates, as in ``recipes/sac_temporal.py``. What differs from training
is only where the episodes come from: a fixed offline set instead of the agent's own.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from torch import Tensor

from temporal_torchrl import defaults
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.defaults import GAP, LABEL_WINDOW, STAGES
from temporal_torchrl.objectives import HEADS_LEARNING_RATE
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.rewards.temporal import renamed_k
from temporal_torchrl.training import RewardHeadTrainer


def make_finetuning_buffer(episodes: Sequence[TensorDictBase], *, stage: int = 2,
                           k: int | None = None, label_window: int | None = LABEL_WINDOW,
                           window_length: int | None = None, gap: int = GAP,
                           embedding_dtype: torch.dtype = torch.float16,
                           history: int | None = None) -> EpisodeReplayBuffer:
    """A replay buffer holding the training episodes the finetuning losses sample from.

    Finetuning stage 2 inserts every episode (positives from the successful ones); finetuning
    stage 1 only the failed ones, so every batch carries negatives alone and the losses run their
    stage-1 form. (The finetuning stage, ``finetune.stage``, is not the protocol stage,
    ``protocol=stage1|stage2``, which says whether expert episodes are preloaded.)

    Args:
        episodes: embedded episodes in ``env.rollout()`` layout.
        stage: the finetuning stage, 1 or 2 (:data:`STAGES`).
        k, label_window, window_length, gap, embedding_dtype: as the training run's
            buffer (``reward.k``, default :data:`~temporal_torchrl.defaults.K`;
            ``reward.label_window``; the reward's ``window_length`` when it reads a window;
            ``reward.gap``; ``replay_buffer.embedding_dtype``).
        history: the deprecated name of ``k`` (a FutureWarning; removed in the next release).
    """
    if stage not in STAGES:
        raise ValueError(f"stage={stage!r}; expected 1 (failed episodes only) or 2 (successful "
                         "ones too).")
    if stage == 1:
        episodes = [e for e in episodes if not bool(e["next", "success"].any())]
    if not episodes:
        raise ValueError("no episodes to finetune on; the training part needs failed episodes "
                         "(stage 1) or any episodes (stage 2).")
    buffer = EpisodeReplayBuffer(sum(len(episode) + 1 for episode in episodes),
                                 k=renamed_k(k, history, "make_finetuning_buffer"),
                                 label_window=label_window, window_length=window_length, gap=gap)
    for episode in episodes:
        buffer.extend(episode_rows(episode, embedding_dtype=embedding_dtype))
    return buffer


def finetune_reward(reward: TemporalReward, buffer: EpisodeReplayBuffer,
                    goal_image_embedding: Tensor, *, updates: int,
                    batch_size: int = defaults.HEADS_BATCH_SIZE,
                    lr: float = HEADS_LEARNING_RATE, delta: float = defaults.DELTA,
                    l2_margin: float = defaults.L2_MARGIN,
                    same_position: bool = defaults.SAME_POSITION) -> dict[str, float]:
    """Train ``reward``'s heads in place for ``updates`` batches; returns the final losses.

    The updates are the training recipe's (:class:`~temporal_torchrl.training.RewardHeadTrainer`:
    one loss per part with heads, by the part's registered objective, each with its own Adam
    optimizer; all read the same batch).

    Args:
        reward: the reward whose heads are trained.
        buffer: the training episodes (:func:`make_finetuning_buffer`; with the reward's
            ``window_length`` when it reads a window).
        goal_image_embedding: s_g, the first success state of a training expert episode
            (:func:`~temporal_torchrl.data.goal_image_embedding`).
        updates: number of batches (>= 0).
        batch_size, lr, delta, l2_margin, same_position: the training recipe's
            ``reward.*`` settings of the same names (``reward.gap`` is the buffer's).

    Returns:
        The mean of each loss over the last ``min(100, updates)`` updates, by loss key
        (empty for a reward without heads or zero updates).
    """
    if isinstance(updates, bool) or not isinstance(updates, int) or updates < 0:
        raise ValueError(f"updates={updates!r}; expected an integer >= 0.")
    trainer = RewardHeadTrainer(reward, goal_image_embedding, buffer.finetuning,
                                batch_size=batch_size, lr=lr, delta=delta, l2_margin=l2_margin,
                                same_position=same_position)
    recent: dict[str, list[Tensor]] = {loss.loss_key: [] for loss in trainer.losses}
    for update in range(updates):
        metrics = trainer.update()
        if update >= updates - 100:
            for key, values in recent.items():
                values.append(metrics[key])
    return {key: float(torch.stack(values).mean()) for key, values in recent.items() if values}
