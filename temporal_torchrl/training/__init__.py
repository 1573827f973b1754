"""The training engine: reward-head trainer, run directory, recipe config, training metrics."""

from temporal_torchrl.training.metrics import MetricWindow, log_metrics, reward_statistics
from temporal_torchrl.training.run import (
    CHECKPOINT,
    EPISODE_COLUMNS,
    LOCK,
    PREVIOUS_CHECKPOINT,
    REPLAY_DIR,
    RunDirectory,
    RunLockedError,
    UnreadableRunFile,
    rng_state,
    set_rng_state,
    write_json,
)
from temporal_torchrl.training.trainer import RewardHeadTrainer

__all__ = [
    "CHECKPOINT",
    "EPISODE_COLUMNS",
    "LOCK",
    "PREVIOUS_CHECKPOINT",
    "REPLAY_DIR",
    "MetricWindow",
    "RewardHeadTrainer",
    "RunDirectory",
    "RunLockedError",
    "UnreadableRunFile",
    "log_metrics",
    "reward_statistics",
    "rng_state",
    "set_rng_state",
    "write_json",
]
