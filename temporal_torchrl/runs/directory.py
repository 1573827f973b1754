"""A training run's directory: config, episode rows, metrics, replay episodes, checkpoints, summary.

Layout::

    <run>/config.json               the resolved config the run started with
    <run>/episodes.csv              one row per finished episode (:data:`EPISODE_COLUMNS`)
    <run>/eval.csv                  with eval.every: one row per evaluation of the deterministic
                                    policy (:data:`EVALUATION_COLUMNS`)
    <run>/metrics.jsonl             one JSON object per logged point of training metrics (below)
    <run>/replay/NNNNNN.pt          the stored rows of every episode inserted into the buffer
    <run>/positives/EEEEEE.pt       with train.save_positives: the rows of each successful
                                    training episode, whole (train.positives_from reads them)
    <run>/checkpoint.pt             networks, optimizers, counters, RNG states (every few episodes)
    <run>/checkpoint.previous.pt    the one before, kept until the new one is complete
    <run>/checkpoint.pt.unreadable  a latest checkpoint a resume could not read, kept aside
    <run>/summary.json              TTFS, TT50S, RAS, throughput (when the run has ended)
    <run>/provenance.json           each start's commit, library versions, CPU and torch threads
    <run>/run.lock, run.lock.json   the writer's lock and who holds it (host, pid, since)
    <run>/logs/, wandb/             the files of the TorchRL logger ``logger.backend`` names

``metrics.jsonl`` (:data:`METRICS_FILE`) is written whatever ``logger.backend`` is and is what
reports read: each line is one JSON object ``{"step": <env steps>, "<key>": <value>, ...}``,
e.g. ``{"step": 2000, "sac/loss_qvalue": 0.42, "sac/alpha": 0.97}``, keys as the recipe logs
them, values numbers (``null`` for a non-finite one), steps non-decreasing, each line flushed
when written. Readers skip a last line without its newline (a kill mid-write).

Guarantees:

- **One writer.** A process holds ``run.lock`` (an OS lock, ``flock`` through ``filelock``) for
  as long as it runs; another process on the same directory stops at once with
  :class:`~temporal_torchrl.runs.RunLockedError`, naming the holder. The OS drops the lock of a
  killed process, so a stale lock never blocks a resume and no lock file ever needs deleting by
  hand.
- **Nothing half-written.** Every file is written to a temporary file, flushed to disk (fsync),
  renamed over the old one, and the directory entry flushed too; ``episodes.csv`` rows are
  appended and flushed the same way. A kill or a power cut leaves the old file or the new one.
- **A fallback checkpoint.** The previous checkpoint is kept until the new one is on disk; a
  resume that finds the latest unreadable continues from the previous one and says so.
- **Resume loses at most the episodes after the checkpoint.** ``episodes.csv``, ``eval.csv``,
  ``replay/``, ``positives/`` and ``metrics.jsonl`` are cut back to the checkpoint resumed from
  (:meth:`RunDirectory.resume_state`) and the replay episodes re-inserted in order, so the
  buffer is rebuilt as it was. An unreadable episode row or replay episode stops the resume
  with :class:`~temporal_torchrl.runs.UnreadableRunFile`, naming the file and the fix.
- An existing run is never replaced unless asked (``overwrite``).

Example:
    >>> import tempfile
    >>> run = RunDirectory(tempfile.mkdtemp() + "/run")
    >>> with run.lock():
    ...     run.check(resume=False, overwrite=False)
    ...     run.create(config={"seed": 0})
    ...     run.append_episode({"episode": 1, "env_steps": 500, "success": 0,
    ...                         "return": -500.0, "mean_vlm_reward": 0.0, "stage": 1})
    >>> [row["env_steps"] for row in run.episode_rows()]
    ['500']
    >>> run.check(resume=False, overwrite=False)
    Traceback (most recent call last):
    ...
    FileExistsError: output_dir=... is not empty and holds no checkpoint.pt to resume from; ...
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tensordict import TensorDict, TensorDictBase

from temporal_torchrl.runs.checkpoint import Checkpoint, CheckpointFiles
from temporal_torchrl.runs.durable import write_json
from temporal_torchrl.runs.episode_log import EpisodeLog
from temporal_torchrl.runs.episode_store import EpisodeStore
from temporal_torchrl.runs.evaluation_log import EvaluationLog
from temporal_torchrl.runs.layout import (
    CHECKPOINT,
    CONFIG_FILE,
    EPISODES_FILE,
    EVALUATION_FILE,
    LOCK_FILES,
    METRICS_FILE,
    POSITIVES_DIR,
    PROVENANCE_FILE,
    REPLAY_DIR,
    SUMMARY_FILE,
)
from temporal_torchrl.runs.lock import RunLock
from temporal_torchrl.runs.metrics_log import MetricsLog


class RunDirectory:
    """One training run's files (see the module doc): the lock (:class:`RunLock`), the
    checkpoints (:class:`CheckpointFiles`), ``episodes.csv`` (:class:`EpisodeLog`), ``eval.csv``
    (:class:`EvaluationLog`), ``metrics.jsonl`` (:class:`MetricsLog`), the stored episodes
    (:class:`EpisodeStore`), and what ties them together: starting, replacing and resuming a run."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.checkpoints = CheckpointFiles(self.path)
        self.episodes = EpisodeLog(self.path / EPISODES_FILE)
        self.evaluations = EvaluationLog(self.path / EVALUATION_FILE)
        self.metrics = MetricsLog(self.path / METRICS_FILE)
        self.replay = EpisodeStore(self.path / REPLAY_DIR)
        self.positives = EpisodeStore(self.path / POSITIVES_DIR)
        self._lock = RunLock(self.path)

    @property
    def checkpoint_path(self) -> Path:
        return self.checkpoints.latest

    @property
    def previous_checkpoint_path(self) -> Path:
        return self.checkpoints.previous

    def has_checkpoint(self) -> bool:
        return self.checkpoints.exist()

    def holds_files(self) -> bool:
        """Whether the directory holds anything besides the lock's own files."""
        return self.path.is_dir() and any(path.name not in LOCK_FILES
                                          for path in self.path.iterdir())

    # ------------------------------------------------------------------ the writer's lock
    @contextmanager
    def lock(self, config: Mapping[str, Any] | None = None) -> Iterator[None]:
        """Hold the run's lock for the ``with`` block (the whole run): raise
        :class:`RunLockedError` at once when a live process holds it. ``config``: the config
        this process runs with, kept beside who holds the lock (:meth:`RunLock.hold`).

        A directory this call had to create and that holds nothing else when the block ends (the
        run stopped before writing a file: bad input, nothing to resume) is removed again.
        """
        created = not self.path.exists()
        self.path.mkdir(parents=True, exist_ok=True)
        empty = False

        def remove_lock_files_if_empty() -> None:
            nonlocal empty
            empty = created and not self.holds_files()
            if empty:  # unlinked before the release: a later process makes a new lock file
                for name in LOCK_FILES:
                    (self.path / name).unlink(missing_ok=True)

        try:
            with self._lock.hold(before_release=remove_lock_files_if_empty, config=config):
                yield
        finally:
            if empty:
                try:
                    self.path.rmdir()
                except OSError:  # another process made it its run in the meantime
                    pass

    def locked_by(self) -> str | None:
        """Who holds the run's lock, None when no live process does (:meth:`RunLock.held_by`)."""
        return self._lock.held_by()

    # ------------------------------------------------------------------ start, replace, resume
    def check(self, *, resume: bool, overwrite: bool) -> None:
        """Raise before any work unless the directory may be resumed, started, or replaced."""
        holds_files = self.holds_files()
        checkpointed = self.has_checkpoint()
        if resume and not checkpointed:
            if holds_files:
                raise FileNotFoundError(
                    f"resume=true but {self.checkpoint_path} does not exist: the run stopped "
                    "before its first checkpoint, so there is nothing to resume. Start it again "
                    "with overwrite=true instead of resume=true.")
            raise FileNotFoundError(f"resume=true but {self.checkpoint_path} does not exist; "
                                    "start the run without resume=true.")
        if not resume and holds_files and not overwrite:
            if checkpointed:
                raise FileExistsError(
                    f"output_dir={str(self.path)!r} already holds a run; pass resume=true to "
                    "continue it, overwrite=true to replace it, or another output_dir.")
            raise FileExistsError(
                f"output_dir={str(self.path)!r} is not empty and holds no {CHECKPOINT} to resume "
                "from; pass overwrite=true to replace its contents, or another output_dir.")

    def create(self, config: dict[str, Any]) -> None:
        """Start the run afresh (after :meth:`check` allowed it): an empty directory but for the
        lock, then the config."""
        self.path.mkdir(parents=True, exist_ok=True)
        for path in self.path.iterdir():
            if path.name in LOCK_FILES:
                continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
        (self.path / REPLAY_DIR).mkdir()
        write_json(self.path / CONFIG_FILE, config)

    def config(self) -> dict[str, Any]:
        return json.loads((self.path / CONFIG_FILE).read_text())

    def resume_state(self) -> Checkpoint:
        """The checkpoint to resume from (the latest readable one, :class:`CheckpointFiles`),
        with ``episodes.csv``, ``eval.csv``, ``metrics.jsonl``, ``replay/`` and ``positives/``
        cut back to it: the rows, points and episodes after it are dropped, as is a summary of a
        longer run."""
        checkpoint = self.checkpoints.load(set_aside=True)
        self.episodes.truncate(checkpoint.episode)
        self.evaluations.truncate(checkpoint.episode)
        self.positives.truncate(checkpoint.episode + 1)  # numbered by episode, from 1
        self.metrics.truncate(checkpoint.env_steps)
        self.replay.truncate(checkpoint.inserted)
        summary = self.summary()
        if summary is not None and summary.get("episodes", 0) > checkpoint.episode:
            (self.path / SUMMARY_FILE).unlink()
        starts = self.provenance()
        if any(start["episode"] > checkpoint.episode for start in starts):
            self._write_provenance([start for start in starts
                                    if start["episode"] <= checkpoint.episode])
        return checkpoint

    def load_checkpoint(self) -> Checkpoint:
        """The latest readable checkpoint, on the CPU (``checkpoint.pt``, else, saying so,
        ``checkpoint.previous.pt``); :class:`UnreadableRunFile` when neither can be read."""
        return self.checkpoints.load()

    def save_checkpoint(self, checkpoint: Checkpoint) -> None:
        """Write the latest checkpoint; the one it replaces becomes the previous checkpoint,
        only once the new one is complete on disk."""
        self.checkpoints.save(checkpoint)

    # ------------------------------------------------------------------ the run's records
    def append_episode(self, row: dict[str, Any]) -> None:
        self.episodes.append(row)

    def episode_rows(self) -> list[dict[str, str]]:
        return self.episodes.rows()

    def append_evaluation(self, row: dict[str, Any]) -> None:
        self.evaluations.append(row)

    def evaluation_rows(self) -> list[dict[str, float]]:
        return self.evaluations.rows()

    def truncate_episodes(self, episodes: int) -> None:
        self.episodes.truncate(episodes)

    @property
    def metrics_path(self) -> Path:
        return self.metrics.path

    def append_metrics(self, step: int, metrics: Mapping[str, float]) -> None:
        self.metrics.append(step, metrics)

    def metric_points(self) -> list[dict[str, Any]]:
        return self.metrics.points()

    def truncate_metrics(self, step: int) -> None:
        self.metrics.truncate(step)

    def save_replay_episode(self, index: int, rows: TensorDictBase) -> None:
        """Save the stored rows of the ``index``-th inserted episode (resume re-inserts them)."""
        self.replay.save(index, rows)

    def replay_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` inserted episodes, in insertion order."""
        return self.replay.first(count)

    def save_positive_episode(self, episode: int, rows: TensorDictBase) -> None:
        """Save the rows of training episode ``episode`` (1-based), a successful one."""
        self.positives.save(episode, rows)

    def saved_positive_count(self) -> int:
        return len(self.positives.indices())

    def positive_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` saved positives, in episode order."""
        for episode in self.positives.indices()[:count]:
            yield self.positives.load(episode)

    def truncate_positives(self, episodes: int) -> None:
        """Drop the positives saved after the checkpoint's ``episodes`` (they are re-run)."""
        self.positives.truncate(episodes + 1)

    def record_start(self, entry: Mapping[str, Any]) -> None:
        """Add one start's provenance entry
        (:func:`~temporal_torchrl.runs.provenance.current_provenance`) to ``provenance.json``."""
        self._write_provenance([*self.provenance(), dict(entry)])

    def provenance(self) -> list[dict[str, Any]]:
        """Each start's provenance entry, oldest first; empty for runs from before the file."""
        path = self.path / PROVENANCE_FILE
        return json.loads(path.read_text())["starts"] if path.exists() else []

    def _write_provenance(self, starts: list[dict[str, Any]]) -> None:
        write_json(self.path / PROVENANCE_FILE, {"starts": starts})

    def write_summary(self, summary: dict[str, Any]) -> None:
        write_json(self.path / SUMMARY_FILE, summary)

    def summary(self) -> dict[str, Any] | None:
        path = self.path / SUMMARY_FILE
        return json.loads(path.read_text()) if path.exists() else None
