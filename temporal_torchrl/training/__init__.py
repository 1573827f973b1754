"""The training loop's parts: the recipe's factories, the reward-head trainer, relay exploration,
the metrics logger and the random generators' state (the recipe's config and its checks:
:mod:`temporal_torchrl.configs`)."""

from temporal_torchrl.training.episodes import STEP_KEYS, EpisodeAssembler, episode_row
from temporal_torchrl.training.logger import (
    MetricWindow,
    RunLogger,
    log_metrics,
    reward_statistics,
)
from temporal_torchrl.training.start import RunStart, start_run
from temporal_torchrl.training.state import (
    TrainingProgress,
    TrainingState,
    UpdateCredits,
    progress_from,
    rng_state,
    set_rng_state,
)
from temporal_torchrl.training.summary import run_summary
from temporal_torchrl.training.trainer import RewardHeadTrainer

__all__ = [
    "STEP_KEYS",
    "EpisodeAssembler",
    "MetricWindow",
    "RewardHeadTrainer",
    "RunStart",
    "RunLogger",
    "TrainingProgress",
    "TrainingState",
    "UpdateCredits",
    "episode_row",
    "log_metrics",
    "progress_from",
    "reward_statistics",
    "rng_state",
    "run_summary",
    "set_rng_state",
    "start_run",
]
