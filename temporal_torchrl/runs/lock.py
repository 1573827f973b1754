"""One writer per run directory: an OS lock (``flock`` through ``filelock``) held for the whole run,
and who holds it. The OS drops the lock of a killed process, so a stale lock never blocks a resume
and no lock file ever needs deleting by hand."""

from __future__ import annotations

import datetime
import json
import os
import socket
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from temporal_torchrl.runs.durable import write_json
from temporal_torchrl.runs.layout import LOCK, LOCK_HOLDER


class RunLockedError(RuntimeError):
    """Another live process holds the run directory's lock.

    Attributes:
        path: the run directory.
        holder: who holds it, e.g. ``"pid 4242 on host node7 (Slurm job 181), since
            2026-12-01T17:03:12+00:00"``.
        holder_config: the config the holder runs with, when it gave one to
            :meth:`RunLock.hold` (None otherwise): a sweep job tells a relaunch of its own run
            from another config's run with it.
    """

    def __init__(self, path: Path, holder: dict[str, Any] | None) -> None:
        self.path, self.holder = path, describe_holder(holder)
        self.holder_config: dict[str, Any] | None = (holder or {}).get("config")
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


class RunLock:
    """The lock of the run directory ``directory``."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    @contextmanager
    def hold(self, before_release: Callable[[], None] = lambda: None,
             config: Mapping[str, Any] | None = None) -> Iterator[None]:
        """Hold the lock for the ``with`` block: :class:`RunLockedError` at once when a live
        process holds it. ``before_release`` runs while the lock is still held, at the end;
        ``config`` (JSON-able), the holder's config, is written beside who holds it."""
        file_lock = FileLock(self.directory / LOCK, timeout=0)
        try:
            file_lock.acquire()
        except Timeout:
            raise RunLockedError(self.directory, self.holder()) from None
        try:
            write_json(self.directory / LOCK_HOLDER, {
                "host": socket.gethostname(), "pid": os.getpid(),
                "since": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                "slurm_job_id": os.environ.get("SLURM_JOB_ID"),
                **({"config": dict(config)} if config is not None else {})})
            yield
        finally:
            try:
                before_release()
            finally:
                file_lock.release()

    def held_by(self) -> str | None:
        """Who holds the lock (as ``RunLockedError.holder``), None when no live process does. A
        probe: the answer may change as soon as it is given."""
        if not (self.directory / LOCK).exists():
            return None
        probe = FileLock(self.directory / LOCK, timeout=0)
        try:
            probe.acquire()
        except Timeout:
            return describe_holder(self.holder())
        probe.release()
        return None

    def holder(self) -> dict[str, Any] | None:
        try:
            holder = json.loads((self.directory / LOCK_HOLDER).read_text())
        except (OSError, ValueError):
            return None
        return holder if isinstance(holder, dict) else None
