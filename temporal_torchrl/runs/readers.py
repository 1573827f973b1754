"""Reading runs back: what the reports need of a run directory, read through the run package.

:func:`find_runs` and :func:`load_run` read a run's config, its episodes' successes, its
evaluations of the deterministic policy (``eval.csv``, when it evaluated) and its summary (a run
still running or killed has no summary); :func:`load_reward` and
:func:`load_episode` read its saved reward heads and its stored episodes.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.rewards.config import reward_from_config
from temporal_torchrl.runs.checkpoint import Checkpoint
from temporal_torchrl.runs.directory import RunDirectory
from temporal_torchrl.runs.episode_log import EpisodeLog
from temporal_torchrl.runs.evaluation_log import EvaluationLog
from temporal_torchrl.runs.layout import (
    CHECKPOINT,
    CONFIG_FILE,
    EPISODES_FILE,
    EVALUATION_FILE,
    PROVENANCE_FILE,
    SUMMARY_FILE,
)

#: Keys that tell the runs of one configuration apart (and put them in different table rows).
RUN_KEYS = ("env.seed", "env.task")


@dataclass(frozen=True)
class Run:
    """One run directory as read from disk.

    Attributes:
        path: the run directory.
        config: its ``config.json`` (the resolved config it ran with).
        successes: ``z_1, z_2, ...`` from ``episodes.csv`` (one per finished episode).
        summary: its ``summary.json``, or None while it runs or after it was killed. A run
            extended with ``resume=true train.episodes=...`` keeps its old summary while it runs
            on, so :attr:`finished` also checks the summary's episode count.
        evaluations: the rows of its ``eval.csv``
            (:class:`~temporal_torchrl.runs.evaluation_log.EvaluationLog`, columns
            :data:`~temporal_torchrl.runs.layout.EVALUATION_COLUMNS` as numbers), in the order
            taken; empty when the run did not evaluate (``eval.every`` unset) or has not yet.
    """

    path: Path
    config: dict[str, Any]
    successes: tuple[bool, ...]
    summary: dict[str, Any] | None
    evaluations: tuple[dict[str, float], ...] = ()

    @property
    def task(self) -> str:
        return self.setting("env.task")

    @property
    def seed(self) -> int:
        return self.setting("env.seed")

    @property
    def episodes(self) -> int:
        return len(self.successes)

    @property
    def finished(self) -> bool:
        """Whether the run wrote its summary after its last episode (and is not running on)."""
        return self.summary is not None and self.summary.get("episodes") == self.episodes

    @property
    def commits(self) -> tuple[str, ...]:
        """The commits its starts ran on (:mod:`~temporal_torchrl.runs.provenance`), first 12
        hex digits each, ``+dirty`` where the tracked files differed from the commit, in order,
        each once; empty for a run from before ``provenance.json`` or outside a git checkout."""
        starts = (self.summary or {}).get("provenance")
        if starts is None:
            path = self.path / PROVENANCE_FILE
            starts = json.loads(path.read_text())["starts"] if path.is_file() else []
        commits = [start["commit"][:12] + ("" if start["clean"] else "+dirty")
                   for start in starts if start.get("commit")]
        return tuple(dict.fromkeys(commits))

    def setting(self, key: str) -> Any:
        """The config value at dotted ``key``; a clear error when the config lacks it."""
        value: Any = self.config
        for part in key.split("."):
            if not isinstance(value, Mapping) or part not in value:
                raise ValueError(f"{self.path / CONFIG_FILE} has no {key!r}: is it a config "
                                 "written by recipes/sac_temporal.py?")
            value = value[part]
        return value


def read_successes(path: Path) -> tuple[bool, ...]:
    """The ``success`` column of an ``episodes.csv`` (empty when the file does not exist),
    each row checked by the rules a resume applies
    (:func:`~temporal_torchrl.runs.episode_log.row_problem`)."""
    return EpisodeLog(path).successes()


def load_run(path: str | Path) -> Run:
    """Read one run directory (``config.json``, ``episodes.csv``, ``eval.csv`` and
    ``summary.json`` if any)."""
    path = Path(path)
    config_path = path / CONFIG_FILE
    if not config_path.is_file():
        raise FileNotFoundError(f"{path} is not a run directory: it has no {CONFIG_FILE}.")
    config = json.loads(config_path.read_text())
    summary_path = path / SUMMARY_FILE
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
    run = Run(path, config, read_successes(path / EPISODES_FILE), summary,
              tuple(EvaluationLog(path / EVALUATION_FILE).rows()))
    for key in RUN_KEYS:
        run.setting(key)  # fail here, naming the file, rather than while grouping
    return run


def find_runs(paths: Iterable[str | Path]) -> list[Run]:
    """Every run directory in or under ``paths`` (each a run or a sweep directory), sorted."""
    found: dict[Path, None] = {}
    for path in map(Path, paths):
        if not path.is_dir():
            raise FileNotFoundError(f"{path} is not a directory; pass run directories or sweep "
                                    "directories that contain them.")
        configs = [path / CONFIG_FILE] if (path / CONFIG_FILE).is_file() else sorted(
            path.rglob(CONFIG_FILE))
        if not configs:
            raise FileNotFoundError(f"no run directory in {path}: looked for {CONFIG_FILE} in it "
                                    "and in every directory below it (recipes/sac_temporal.py "
                                    "writes one into each run directory).")
        for config in configs:
            found[config.parent.resolve()] = None
    return [load_run(path) for path in sorted(found)]


def load_reward(run_dir: str | Path) -> tuple[TemporalReward, Checkpoint]:
    """The run's reward with the heads of its latest readable checkpoint (falling back to the
    previous one as a resume does), and that checkpoint (for its ``preloaded``, ``inserted`` and
    ``episode``).

    Rewards registered by the run's ``reward.modules`` must be imported first.
    """
    run = RunDirectory(run_dir)
    if not run.has_checkpoint():
        raise FileNotFoundError(f"{run.path} has no {CHECKPOINT}: the reward heads are saved "
                                "there after each checkpointed episode.")
    checkpoint = run.load_checkpoint()
    state = checkpoint.reward
    if not state:
        raise ValueError(f"{run.path} has no VLM reward (reward.positional and "
                         "reward.directional are none): there are no r_P, r_D to plot.")
    reward = reward_from_config(run.config(), state["goal_embedding"], state["baseline_embedding"])
    reward.load_state_dict(state)
    return reward.eval(), checkpoint


def load_episode(run_dir: str | Path, index: int) -> dict[str, torch.Tensor]:
    """The stored rows of the run's ``index``-th inserted episode."""
    rows = RunDirectory(run_dir).replay.load(index)
    if "embedding" not in rows.keys():
        raise ValueError(f"{RunDirectory(run_dir).replay.path(index)} stores no embeddings: the "
                         "run has no VLM reward.")
    return rows.to_dict()
