"""What a training run is, outside the loop that trains it.

Its directory and files (:mod:`~temporal_torchrl.runs.directory`,
:mod:`~temporal_torchrl.runs.layout`), its name (:mod:`~temporal_torchrl.runs.naming`), how it
resumes and how sweep jobs find it (:mod:`~temporal_torchrl.runs.resume`), and reading it back
(:mod:`~temporal_torchrl.runs.readers`; its reward is built by
:func:`temporal_torchrl.rewards.reward_from_config`). The recipe writes runs through this
package and the reports read them through it.

:mod:`~temporal_torchrl.runs.sweep_job` is imported by name, not from here: its child process
runs it as ``python -m``, which warns when the package has imported the module already."""

from temporal_torchrl.runs.checkpoint import (
    CHECKPOINT_VERSION,
    Checkpoint,
    CheckpointFiles,
    UnreadableRunFile,
)
from temporal_torchrl.runs.directory import RunDirectory
from temporal_torchrl.runs.durable import write_json
from temporal_torchrl.runs.episode_log import EpisodeLog
from temporal_torchrl.runs.episode_store import EpisodeStore
from temporal_torchrl.runs.evaluation_log import EvaluationLog, evaluation_summary
from temporal_torchrl.runs.layout import (
    CHECKPOINT,
    CONFIG_FILE,
    EPISODE_COLUMNS,
    EPISODES_FILE,
    EVALUATION_COLUMNS,
    EVALUATION_FILE,
    LOCK,
    METRICS_FILE,
    POSITIVES_DIR,
    PREVIOUS_CHECKPOINT,
    PROTOCOLS,
    REPLAY_DIR,
    SUMMARY_FILE,
    flatten,
    protocol_name,
)
from temporal_torchrl.runs.lock import RunLock, RunLockedError
from temporal_torchrl.runs.metrics_log import MetricsLog
from temporal_torchrl.runs.naming import default_run_dir, run_directory
from temporal_torchrl.runs.readers import (
    RUN_KEYS,
    Run,
    find_runs,
    load_episode,
    load_reward,
    load_run,
    read_successes,
)
from temporal_torchrl.runs.resume import (
    DEVICE_KEYS,
    PROCESS_KEYS,
    RESUMABLE_KEYS,
    RunConflictError,
    check_no_conflict,
    check_positives_source,
    conflicting_values,
    override_keys,
    resumed_config,
    sweep_job_config,
    threads_per_job,
)

__all__ = [
    "CHECKPOINT_VERSION",
    "Checkpoint",
    "CheckpointFiles",
    "EpisodeLog",
    "EpisodeStore",
    "EvaluationLog",
    "MetricsLog",
    "RunLock",
    "CHECKPOINT",
    "CONFIG_FILE",
    "DEVICE_KEYS",
    "EPISODES_FILE",
    "EPISODE_COLUMNS",
    "EVALUATION_COLUMNS",
    "EVALUATION_FILE",
    "LOCK",
    "METRICS_FILE",
    "POSITIVES_DIR",
    "PREVIOUS_CHECKPOINT",
    "PROCESS_KEYS",
    "PROTOCOLS",
    "REPLAY_DIR",
    "RESUMABLE_KEYS",
    "RUN_KEYS",
    "SUMMARY_FILE",
    "Run",
    "RunConflictError",
    "RunDirectory",
    "RunLockedError",
    "UnreadableRunFile",
    "check_no_conflict",
    "check_positives_source",
    "conflicting_values",
    "default_run_dir",
    "evaluation_summary",
    "find_runs",
    "flatten",
    "load_episode",
    "load_reward",
    "load_run",
    "override_keys",
    "protocol_name",
    "read_successes",
    "resumed_config",
    "run_directory",
    "sweep_job_config",
    "threads_per_job",
    "write_json",
]
