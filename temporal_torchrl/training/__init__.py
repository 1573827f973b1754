"""The training loop's parts: the recipe's factories, the reward-head trainer, relay exploration,
the metrics logger and the random generators' state (the recipe's config and its checks:
:mod:`temporal_torchrl.configs`)."""

from temporal_torchrl.training.logger import (
    MetricWindow,
    RunLogger,
    log_metrics,
    reward_statistics,
)
from temporal_torchrl.training.state import rng_state, set_rng_state
from temporal_torchrl.training.trainer import RewardHeadTrainer

__all__ = [
    "MetricWindow",
    "RewardHeadTrainer",
    "RunLogger",
    "log_metrics",
    "reward_statistics",
    "rng_state",
    "set_rng_state",
]
