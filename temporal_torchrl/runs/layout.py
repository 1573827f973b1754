"""A run directory's file names and a run's protocol names: the one place that defines them.

:class:`~temporal_torchrl.runs.RunDirectory` writes these files; the reports read them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from temporal_torchrl import defaults

CONFIG_FILE = "config.json"
EPISODES_FILE = "episodes.csv"
#: Evaluations of the deterministic policy (``eval.every``).
EVALUATION_FILE = "eval.csv"
SUMMARY_FILE = "summary.json"
#: Where each start of the run ran (:mod:`~temporal_torchrl.runs.provenance`).
PROVENANCE_FILE = "provenance.json"
CHECKPOINT = "checkpoint.pt"
#: The checkpoint before the latest, kept until the new one is complete on disk.
PREVIOUS_CHECKPOINT = "checkpoint.previous.pt"
#: Where a resume moves a latest checkpoint it could not read.
UNREADABLE_CHECKPOINT = "checkpoint.pt.unreadable"
LOCK = "run.lock"
#: Who holds the lock (host, pid, since, Slurm job).
LOCK_HOLDER = "run.lock.json"
#: Files of the lock itself: they do not make a directory hold a run.
LOCK_FILES = (LOCK, LOCK_HOLDER)
#: The folder of the TorchRL CSV logger's files.
LOGS_DIR = "logs"
METRICS_FILE = "metrics.jsonl"
REPLAY_DIR = "replay"
POSITIVES_DIR = "positives"
#: The columns of ``episodes.csv``.
EPISODE_COLUMNS = ("episode", "env_steps", "success", "return", "mean_vlm_reward", "stage")
#: The columns of ``eval.csv`` (:class:`~temporal_torchrl.runs.evaluation_log.EvaluationLog`).
EVALUATION_COLUMNS = ("episode", "env_steps", "episodes", "success_rate", "final_success_rate",
                      "return", "episode_length")


def episode_file(index: int) -> str:
    """The name of the ``index``-th inserted episode's file in ``replay/`` (and of training
    episode ``index``'s in ``positives/``)."""
    return f"{index:06d}.pt"


#: Preloaded positive episodes of each protocol of the thesis (section 5.1).
PROTOCOLS = {0: "stage1", defaults.STAGE2_POSITIVES: "stage2"}


def protocol_name(preload_positives: int) -> str:
    """``stage1`` (no preloaded episodes), ``stage2``
    (:data:`~temporal_torchrl.defaults.STAGE2_POSITIVES`), else ``preload<N>``."""
    return PROTOCOLS.get(preload_positives, f"preload{preload_positives}")


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"reward": {"rho": 1.0}}`` -> ``{"reward.rho": 1.0}`` (lists and empty groups stay
    values)."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping) and value:
            flat.update(flatten(value, name))
        else:
            flat[name] = value
    return flat
