"""A training run's directory: config, episode rows, metrics, replay episodes, checkpoints, summary.

Layout::

    <run>/config.json               the resolved config the run started with
    <run>/episodes.csv              one row per finished episode (:data:`EPISODE_COLUMNS`)
    <run>/metrics.jsonl             one JSON object per logged point of training metrics (below)
    <run>/replay/NNNNNN.pt          the stored rows of every episode inserted into the buffer
    <run>/positives/EEEEEE.pt       with train.save_positives: the rows of each successful
                                    training episode, whole (train.positives_from reads them)
    <run>/checkpoint.pt             networks, optimizers, counters, RNG states (every few episodes)
    <run>/checkpoint.previous.pt    the one before, kept until the new one is complete
    <run>/checkpoint.pt.unreadable  a latest checkpoint a resume could not read, kept aside
    <run>/summary.json              TTFS, TT50S, RAS, throughput (when the run has ended)
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
  :class:`RunLockedError`, naming the holder. The OS drops the lock of a killed process, so a
  stale lock never blocks a resume and no lock file ever needs deleting by hand.
- **Nothing half-written.** Every file is written to a temporary file, flushed to disk (fsync),
  renamed over the old one, and the directory entry flushed too; ``episodes.csv`` rows are
  appended and flushed the same way. A kill or a power cut leaves the old file or the new one.
- **A fallback checkpoint.** The previous checkpoint is kept until the new one is on disk; a
  resume that finds the latest unreadable continues from the previous one and says so.
- **Resume loses at most the episodes after the checkpoint.** ``episodes.csv``, ``replay/``,
  ``positives/`` and ``metrics.jsonl`` are cut back to the checkpoint resumed from
  (:meth:`RunDirectory.resume_state`) and the replay episodes re-inserted in order, so the
  buffer is rebuilt as it was. An unreadable episode row or replay episode stops the resume
  with :class:`UnreadableRunFile`, naming the file and the fix.
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

import csv
import datetime
import io
import json
import math
import os
import shutil
import socket
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import torch
from filelock import FileLock, Timeout
from tensordict import TensorDict, TensorDictBase

from temporal_torchrl.runs.layout import (
    CHECKPOINT,
    CONFIG_FILE,
    EPISODE_COLUMNS,
    EPISODES_FILE,
    METRICS_FILE,
    POSITIVES_DIR,
    REPLAY_DIR,
    SUMMARY_FILE,
    episode_file,
)

PREVIOUS_CHECKPOINT = "checkpoint.previous.pt"
#: Where a resume moves a latest checkpoint it could not read.
UNREADABLE_CHECKPOINT = "checkpoint.pt.unreadable"
LOCK = "run.lock"
LOCK_HOLDER = "run.lock.json"
#: Files of the lock itself: they do not make a directory hold a run.
LOCK_FILES = (LOCK, LOCK_HOLDER)
_START_OVER = "start the run over with overwrite=true (this deletes its files)"


class RunLockedError(RuntimeError):
    """Another live process holds the run directory's lock.

    Attributes:
        path: the run directory.
        holder: who holds it, e.g. ``"pid 4242 on host node7 (Slurm job 181), since
            2026-12-01T17:03:12+00:00"``.
    """

    def __init__(self, path: Path, holder: dict[str, Any] | None) -> None:
        self.path, self.holder = path, describe_holder(holder)
        if holder is None:
            stop = "stop it"
        elif holder.get("slurm_job_id"):
            stop = f"stop it (scancel {holder['slurm_job_id']})"
        else:
            stop = f"stop it (kill {holder.get('pid')} on {holder.get('host')})"
        super().__init__(
            f"output_dir={str(path)!r} is in use: {self.holder} is writing this run (it holds "
            f"{path / LOCK}). One process at a time may write a run. Wait for that process to "
            f"end, or {stop}, then continue the run with resume=true (a killed process releases "
            "the lock at once: there is no lock file to delete); or pass another output_dir.")

    def skip_line(self) -> str:
        """What a sweep job prints when it leaves a run alone that a live job is writing."""
        return (f"{self.path}: skipped, {self.holder} is writing this run; launch the sweep again "
                "after it has ended to continue the run")


def describe_holder(holder: dict[str, Any] | None) -> str:
    """``pid P on host H (Slurm job J), since T`` from a lock's ``run.lock.json``."""
    if holder is None:
        return f"another process (its details, {LOCK_HOLDER}, are not written yet)"
    text = f"pid {holder.get('pid')} on host {holder.get('host')}"
    if holder.get("slurm_job_id"):
        text += f" (Slurm job {holder['slurm_job_id']})"
    return f"{text}, since {holder.get('since')}"


class UnreadableRunFile(RuntimeError):
    """A file a resume needs is missing or unreadable; the message names it and the fix."""


class RunDirectory:
    """One training run's files (see the module doc)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    @property
    def checkpoint_path(self) -> Path:
        return self.path / CHECKPOINT

    @property
    def previous_checkpoint_path(self) -> Path:
        return self.path / PREVIOUS_CHECKPOINT

    def has_checkpoint(self) -> bool:
        # A kill between the two renames of save_checkpoint leaves only the previous one.
        return self.checkpoint_path.exists() or self.previous_checkpoint_path.exists()

    def holds_files(self) -> bool:
        """Whether the directory holds anything besides the lock's own files."""
        return self.path.is_dir() and any(path.name not in LOCK_FILES
                                          for path in self.path.iterdir())

    # ------------------------------------------------------------------ the writer's lock
    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the run's lock for the ``with`` block (the whole run): raise
        :class:`RunLockedError` at once when a live process holds it.

        A directory this call had to create and that holds nothing else when the block ends (the
        run stopped before writing a file: bad input, nothing to resume) is removed again.
        """
        created = not self.path.exists()
        self.path.mkdir(parents=True, exist_ok=True)
        file_lock = FileLock(self.path / LOCK, timeout=0)
        try:
            file_lock.acquire()
        except Timeout:
            raise RunLockedError(self.path, self._holder()) from None
        try:
            job = os.environ.get("SLURM_JOB_ID")
            write_json(self.path / LOCK_HOLDER, {
                "host": socket.gethostname(), "pid": os.getpid(),
                "since": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                "slurm_job_id": job})
            yield
        finally:
            empty = created and not self.holds_files()
            if empty:  # unlinked before the release: a later process makes a new lock file
                for name in LOCK_FILES:
                    (self.path / name).unlink(missing_ok=True)
            file_lock.release()
            if empty:
                try:
                    self.path.rmdir()
                except OSError:  # another process made it its run in the meantime
                    pass

    def locked_by(self) -> str | None:
        """Who holds the run's lock (as ``RunLockedError.holder``), None when no live process
        does. A probe: the answer may change as soon as it is given."""
        if not (self.path / LOCK).exists():
            return None
        probe = FileLock(self.path / LOCK, timeout=0)
        try:
            probe.acquire()
        except Timeout:
            return describe_holder(self._holder())
        probe.release()
        return None

    def _holder(self) -> dict[str, Any] | None:
        try:
            holder = json.loads((self.path / LOCK_HOLDER).read_text())
        except (OSError, ValueError):
            return None
        return holder if isinstance(holder, dict) else None

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

    def resume_state(self) -> dict[str, Any]:
        """The state to resume from (:meth:`load_checkpoint`, falling back to the previous
        checkpoint), with ``episodes.csv`` and ``replay/`` cut back to it: the rows and replay
        episodes of the episodes after it are dropped, as is a summary of a longer run."""
        state, fallback = self._load_checkpoint()
        if fallback is not None:
            if self.checkpoint_path.exists():
                # Kept for a look, but out of the way: the next checkpoint would otherwise make
                # it the previous one, the fallback of the next resume.
                os.replace(self.checkpoint_path, self.path / UNREADABLE_CHECKPOINT)
                fallback += f" (the unreadable one is kept as {UNREADABLE_CHECKPOINT})"
            print(fallback)
        self.truncate_episodes(state["episode"])
        self.truncate_positives(state["episode"])
        self.truncate_metrics(state["env_steps"])
        replay = self.path / REPLAY_DIR
        if replay.is_dir():  # (without it, replay_episodes names the first missing episode)
            for path in replay.iterdir():
                after = path.stem.isdigit() and int(path.stem) >= state["inserted"]
                if after or path.suffix == ".tmp":
                    path.unlink()
            fsync_directory(replay)
        summary = self.summary()
        if summary is not None and summary.get("episodes", 0) > state["episode"]:
            (self.path / SUMMARY_FILE).unlink()
        return state

    # ------------------------------------------------------------------ episode rows
    def append_episode(self, row: dict[str, Any]) -> None:
        path = self.path / EPISODES_FILE
        new = not path.exists()
        with path.open("a", newline="") as file:
            writer = csv.DictWriter(file, fieldnames=EPISODE_COLUMNS)
            if new:
                writer.writeheader()
            writer.writerow(row)
            _flush_to_disk(file)
        if new:
            fsync_directory(self.path)

    def episode_rows(self) -> list[dict[str, str]]:
        path = self.path / EPISODES_FILE
        if not path.exists():
            return []
        with path.open(newline="") as file:
            return list(csv.DictReader(file))

    def truncate_episodes(self, episodes: int) -> None:
        """Keep the first ``episodes`` rows (those the checkpoint covers) after a kill; raise
        :class:`UnreadableRunFile` when one of them is missing or unreadable."""
        path = self.path / EPISODES_FILE
        rows = self.episode_rows()
        for number, row in enumerate(rows[:episodes], start=1):
            problem = _row_problem(row, number)
            if problem is not None:
                shown = ",".join("" if value is None else str(value) for value in row.values())
                raise UnreadableRunFile(
                    f"{path}, line {number + 1} ({shown!r}), is unreadable: {problem}; expected "
                    f"{','.join(EPISODE_COLUMNS)} of episode {number}, which the checkpoint "
                    "covers. Repair that line (or restore the file from a backup) and resume "
                    f"again, or {_START_OVER}.")
        if len(rows) < episodes:
            raise UnreadableRunFile(
                f"{path} holds {len(rows)} episode rows but the checkpoint covers {episodes} "
                "episodes: rows were lost. Restore the file from a backup and resume again, or "
                f"{_START_OVER}.")
        if len(rows) == episodes and path.exists():
            return
        write_file(path, lambda file: _write_rows(file, rows[:episodes]))

    # ------------------------------------------------------------------ training metrics
    @property
    def metrics_path(self) -> Path:
        return self.path / METRICS_FILE

    def append_metrics(self, step: int, metrics: Mapping[str, float]) -> None:
        """Append one point, ``{"step": step, **metrics}``, to ``metrics.jsonl``; the line is on
        disk (flushed, the file closed) when this returns."""
        if "step" in metrics:
            raise ValueError(f"a metric named 'step' clashes with {METRICS_FILE}'s step field; "
                             "log it under another key (e.g. 'train/step').")
        point = {"step": int(step)}
        for key, value in metrics.items():
            value = float(value)
            point[key] = value if math.isfinite(value) else None  # NaN is not JSON
        with self.metrics_path.open("a") as file:
            file.write(json.dumps(point) + "\n")

    def metric_points(self) -> list[dict[str, Any]]:
        """The points of ``metrics.jsonl`` in the order written (empty when there is none);
        a last line cut short by a kill is skipped, any other bad line raises."""
        path = self.metrics_path
        if not path.exists():
            return []
        text = path.read_text()
        lines = text.split("\n")
        points = []
        for number, line in enumerate(lines, start=1):
            if not line.strip():
                continue
            try:
                point = json.loads(line)
            except json.JSONDecodeError as error:
                if number == len(lines):  # no newline after it: the write was cut short
                    break
                raise ValueError(f"{path}:{number} is not JSON ({error}); expected one object "
                                 'per line, {"step": <env steps>, "<key>": <number>, ...}.'
                                 ) from error
            if (not isinstance(point, dict) or isinstance(point.get("step"), bool)
                    or not isinstance(point.get("step"), int)
                    or not all(value is None or (isinstance(value, int | float)
                                                 and not isinstance(value, bool))
                               for value in point.values())):
                raise ValueError(f"{path}:{number}: {line!r}; expected an object with an "
                                 'integer "step" and numbers (or null) as values, '
                                 'e.g. {"step": 2000, "sac/alpha": 0.97}.')
            points.append(point)
        return points

    def truncate_metrics(self, step: int) -> None:
        """Keep the points up to env step ``step`` (those the checkpoint covers) after a kill,
        so that the steps the resumed run logs again are not there twice."""
        if not self.metrics_path.exists():
            return
        kept = "".join(json.dumps(point) + "\n" for point in self.metric_points()
                       if point["step"] <= step)
        write_file(self.metrics_path, lambda file: file.write(kept.encode()))

    # ------------------------------------------------------------------ replay
    def save_replay_episode(self, index: int, rows: TensorDictBase) -> None:
        """Save the stored rows of the ``index``-th inserted episode (resume re-inserts them)."""
        data = rows.cpu().to_dict()
        path = self.path / REPLAY_DIR / episode_file(index)
        write_file(path, lambda file: torch.save(data, file))

    def replay_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` inserted episodes, in insertion order; raise
        :class:`UnreadableRunFile` naming a missing or unreadable one."""
        for index in range(count):
            path = self.path / REPLAY_DIR / episode_file(index)
            try:
                data = torch.load(path, weights_only=True)
                rows = TensorDict(data, [data["step"].shape[0]])
            except Exception as error:  # noqa: BLE001 (any failure to read means the same)
                raise UnreadableRunFile(
                    f"replay episode {path} is unreadable ({type(error).__name__}: {error}). A "
                    f"resume rebuilds the replay buffer from the first {count} replay episodes, "
                    "so this run cannot continue exactly without it: restore the file from a "
                    f"backup and resume again, or {_START_OVER}.") from error
            yield rows

    # ------------------------------------------------------------------ saved positives
    def save_positive_episode(self, episode: int, rows: TensorDictBase) -> None:
        """Save the rows of training episode ``episode`` (1-based), a successful one."""
        directory = self.path / POSITIVES_DIR
        directory.mkdir(exist_ok=True)
        data = rows.cpu().to_dict()
        write_file(directory / episode_file(episode), lambda file: torch.save(data, file))

    def _positive_paths(self) -> list[Path]:
        directory = self.path / POSITIVES_DIR
        return sorted(directory.glob("*.pt")) if directory.is_dir() else []

    def saved_positive_count(self) -> int:
        return len(self._positive_paths())

    def positive_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` saved positives, in episode order."""
        for path in self._positive_paths()[:count]:
            data = torch.load(path, weights_only=True)
            yield TensorDict(data, [data["step"].shape[0]])

    def truncate_positives(self, episodes: int) -> None:
        """Drop the positives saved after the checkpoint's ``episodes`` (they are re-run)."""
        for path in self._positive_paths():
            if int(path.stem) > episodes:
                path.unlink()

    # ------------------------------------------------------------------ checkpoint, summary
    def save_checkpoint(self, state: dict[str, Any]) -> None:
        """Write ``state`` as the latest checkpoint; the one it replaces becomes the previous
        checkpoint, only once the new one is complete on disk."""
        temporary = self.path / (CHECKPOINT + ".tmp")
        write_synced(temporary, lambda file: torch.save(state, file))
        if self.checkpoint_path.exists():
            os.replace(self.checkpoint_path, self.previous_checkpoint_path)
        os.replace(temporary, self.checkpoint_path)
        fsync_directory(self.path)

    def load_checkpoint(self) -> dict[str, Any]:
        """The latest readable checkpoint's state, on the CPU (``load_state_dict`` copies it to
        the modules' devices): ``checkpoint.pt``, else (saying so) ``checkpoint.previous.pt``;
        :class:`UnreadableRunFile` when neither can be read."""
        state, fallback = self._load_checkpoint()
        if fallback is not None:
            print(fallback)
        return state

    def _load_checkpoint(self) -> tuple[dict[str, Any], str | None]:
        """The latest readable state, and the line saying why it is the previous one (None
        when it is the latest)."""
        problems = []
        for path in (self.checkpoint_path, self.previous_checkpoint_path):
            if not path.exists():
                problems.append(f"{path.name} does not exist")
                continue
            try:
                state = torch.load(path, map_location="cpu", weights_only=True)
                if not isinstance(state, dict):
                    raise TypeError(f"it holds a {type(state).__name__}, not a state dict")
            except Exception as error:  # noqa: BLE001 (any failure to read means the same)
                problems.append(f"{path.name} is unreadable ({type(error).__name__}: {error})")
                continue
            fallback = None
            if problems:
                fallback = (f"resume: {problems[0]}; continuing from the previous checkpoint, "
                            f"{path} (episode {state.get('episode')}): the episodes after it run "
                            "again")
            return state, fallback
        raise UnreadableRunFile(
            f"no readable checkpoint in {self.path}: {'; '.join(problems)}. Restore "
            f"{CHECKPOINT} from a backup and resume again, or {_START_OVER}.")

    def write_summary(self, summary: dict[str, Any]) -> None:
        write_json(self.path / SUMMARY_FILE, summary)

    def summary(self) -> dict[str, Any] | None:
        path = self.path / SUMMARY_FILE
        return json.loads(path.read_text()) if path.exists() else None


def _row_problem(row: dict[str | None, Any], number: int) -> str | None:
    """What is wrong with the ``number``-th episode row, None when nothing is."""
    if None in row:
        return "it has more columns than the header"
    missing = [column for column in EPISODE_COLUMNS if row.get(column) in (None, "")]
    if missing:
        return f"{', '.join(missing)} missing (the line was cut short)"
    try:
        values = [float(row[column]) for column in EPISODE_COLUMNS]
    except ValueError as error:
        return f"a value is not a number ({error})"
    if values[0] != number:
        return f"it is numbered {row['episode']}, not {number}"
    return None


def _write_rows(file: IO[bytes], rows: list[dict[str, str]]) -> None:
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=EPISODE_COLUMNS)
    writer.writeheader()
    writer.writerows(rows)
    file.write(text.getvalue().encode())


def _flush_to_disk(file: IO) -> None:
    file.flush()
    os.fsync(file.fileno())


def fsync_directory(path: Path) -> None:
    """Flush a directory's entries (a rename, a new file) to disk."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def write_synced(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Create ``path`` with what ``write`` writes into it, flushed to disk before returning."""
    with path.open("wb") as file:
        write(file)
        _flush_to_disk(file)


def write_file(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` whole: ``write`` fills a temporary file, which is flushed to disk and
    renamed over ``path``; then the rename itself is flushed (the directory entry)."""
    temporary = path.with_name(path.name + ".tmp")
    write_synced(temporary, write)
    os.replace(temporary, path)
    fsync_directory(path.parent)


def write_json(path: str | Path, payload: Mapping[str, Any]) -> None:
    """``payload`` as indented JSON, written whole (:func:`write_file`)."""
    write_file(Path(path), lambda file: file.write((json.dumps(payload, indent=2) + "\n").encode()))
