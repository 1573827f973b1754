"""Offline reward-quality benchmark: score reward variants and encoders without RL.

Collect embedded successful and failed episodes of a task (:mod:`.dataset`), finetune a reward's
heads on the training part with the package's own losses (:mod:`.offline_finetuning`), and score the
rewards on the held-out part (:mod:`.scoring`, :mod:`.metrics`): value-order correlation, AUROC
and direction accuracy. :mod:`.outputs` writes the tables, JSON and figures;
``recipes/evaluate_rewards.py`` runs the whole benchmark.
"""

from temporal_torchrl.reward_quality.dataset import (
    EPISODE_KINDS,
    DatasetSpec,
    RewardDataset,
    collect_reward_dataset,
    load_or_collect,
    split_by_episode,
)
from temporal_torchrl.reward_quality.metrics import (
    auroc,
    average_ranks,
    direction_accuracy,
    spearman_correlation,
    value_order_correlation,
)
from temporal_torchrl.reward_quality.offline_finetuning import (
    STAGES,
    finetune_reward,
    make_finetuning_buffer,
)
from temporal_torchrl.reward_quality.scoring import (
    RewardScores,
    backward_rewards,
    episode_embeddings,
    reward_curve,
    score_reward,
    state_rewards,
    success_length,
)

__all__ = [
    "EPISODE_KINDS",
    "STAGES",
    "DatasetSpec",
    "RewardDataset",
    "RewardScores",
    "auroc",
    "average_ranks",
    "backward_rewards",
    "collect_reward_dataset",
    "direction_accuracy",
    "episode_embeddings",
    "finetune_reward",
    "load_or_collect",
    "make_finetuning_buffer",
    "reward_curve",
    "score_reward",
    "spearman_correlation",
    "split_by_episode",
    "state_rewards",
    "success_length",
    "value_order_correlation",
]
