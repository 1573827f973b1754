"""Offline reward-quality benchmark: score reward variants and encoders without RL.

Collect embedded successful and failed episodes of a task (:mod:`.dataset`), finetune a reward's
heads on the training part with the package's own losses (:mod:`.offline_finetuning`), and score the
rewards on the held-out part (:mod:`.scoring`, :mod:`.metrics`): value-order correlation, AUROC
and direction accuracy. :mod:`.tasks` prepares one task of the benchmark's config (its dataset,
split and text embeddings), :mod:`.outputs` writes the tables, JSON and figures;
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
from temporal_torchrl.reward_quality.tasks import (
    TaskData,
    dataset_spec,
    prepare_task,
    task_config,
)

__all__ = [
    "EPISODE_KINDS",
    "STAGES",
    "DatasetSpec",
    "RewardDataset",
    "RewardScores",
    "TaskData",
    "auroc",
    "average_ranks",
    "backward_rewards",
    "collect_reward_dataset",
    "dataset_spec",
    "direction_accuracy",
    "episode_embeddings",
    "finetune_reward",
    "load_or_collect",
    "make_finetuning_buffer",
    "prepare_task",
    "reward_curve",
    "score_reward",
    "spearman_correlation",
    "split_by_episode",
    "state_rewards",
    "success_length",
    "task_config",
    "value_order_correlation",
]
