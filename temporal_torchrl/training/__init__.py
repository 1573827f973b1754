"""The training engine: reward-head trainer, run directory, recipe config, training metrics."""

from temporal_torchrl.training.logger import (
    MetricWindow,
    RunLogger,
    log_metrics,
    reward_statistics,
)
from temporal_torchrl.training.run import (
    CHECKPOINT,
    EPISODE_COLUMNS,
    LOCK,
    METRICS_FILE,
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
    "METRICS_FILE",
    "LOCK",
    "PREVIOUS_CHECKPOINT",
    "REPLAY_DIR",
    "MetricWindow",
    "RewardHeadTrainer",
    "RunDirectory",
    "RunLogger",
    "RunLockedError",
    "UnreadableRunFile",
    "log_metrics",
    "reward_statistics",
    "rng_state",
    "set_rng_state",
    "write_json",
]
