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
    METRICS_FILE,
    REPLAY_DIR,
    RunDirectory,
    rng_state,
    set_rng_state,
    write_json,
)
from temporal_torchrl.training.trainer import RewardHeadTrainer

__all__ = [
    "CHECKPOINT",
    "EPISODE_COLUMNS",
    "METRICS_FILE",
    "REPLAY_DIR",
    "MetricWindow",
    "RewardHeadTrainer",
    "RunDirectory",
    "RunLogger",
    "log_metrics",
    "reward_statistics",
    "rng_state",
    "set_rng_state",
    "write_json",
]
