"""One job of a sweep, run in a process of its own, so that its death is reported by name.

Hydra's launchers run a job's function inside their own worker (a loky process for joblib, the
Slurm job for submitit, the main process for the basic launcher). An exception there is stored
and raised only once the whole batch has ended, hours later in a study; a job killed from
outside (``kill -9``, the kernel's OOM killer) takes a joblib worker with it and the sweep
stops with the worker's exit code, not the job's. :func:`run_sweep_job` runs the training
function in a child process instead and waits for it. Whatever ends the child early, it prints
at once, and raises, a :class:`SweepJobFailed` that names the job, its run directory and the
exception or signal. The other jobs go on; Hydra raises the error when the batch ends, so the
sweep exits non-zero. Launching the same command again resumes the run from its checkpoint
(:func:`~temporal_torchrl.runs.resume.sweep_job_config`).

The child (``python -m temporal_torchrl.runs.sweep_job <job file>``) imports the recipe script
and calls its function on the job's resolved config; it dies with its parent, so a killed worker
leaves no orphan writing the run.
"""

from __future__ import annotations

import ctypes
import json
import os
import runpy
import signal
import subprocess
import sys
import tempfile
import traceback
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from temporal_torchrl.runs.lock import RunLockedError
from temporal_torchrl.runs.resume import RunConflictError, conflicting_values

#: The child's exit status when it left the run to the live process that holds its lock.
_SKIPPED = 3
#: What a job killed or failed in the middle of its run does next.
_RESUME = "Launch the same command again to resume it from its last checkpoint."


class SweepJobFailed(RuntimeError):
    """A sweep job's training process ended without finishing its run (the message says how)."""


def describe_exit(returncode: int) -> str:
    """What a child's exit status says: ``killed by SIGKILL (...)`` or ``exited with status N``."""
    if returncode >= 0:
        return f"exited with status {returncode}"
    try:
        name = signal.Signals(-returncode).name
    except ValueError:
        name = f"signal {-returncode}"
    cause = {"SIGKILL": " (kill -9, the kernel's OOM killer, or a scheduler's hard limit)",
             "SIGSEGV": " (a segmentation fault in native code)",
             "SIGTERM": " (kill, or a scheduler stopping the job)"}.get(name, "")
    return f"killed by {name}{cause}"


def run_sweep_job(script: str | Path, function: str, cfg: DictConfig,
                  given_keys: Collection[str], job: str, run_dir: Path) -> None:
    """Run ``function(cfg, given_keys)`` of the recipe ``script`` in a child process.

    ``job`` names the job in messages (Hydra's ``#<num> : <overrides>``); ``run_dir`` is its
    run directory. Returns when the child finished (or skipped a run another live process is
    writing); raises :class:`SweepJobFailed` otherwise, after printing the same message.
    """
    with tempfile.TemporaryDirectory(prefix="sweep_job_") as folder:
        job_file, result_file = Path(folder) / "job.json", Path(folder) / "result.json"
        job_file.write_text(json.dumps({
            "script": str(Path(script).resolve()), "function": function,
            "config": OmegaConf.to_container(cfg, resolve=True),
            "given_keys": sorted(given_keys), "result": str(result_file)}))
        sys.stdout.flush()
        returncode = subprocess.run([sys.executable, "-m", __name__, str(job_file)]).returncode
        if returncode in (0, _SKIPPED):
            return
        failure = json.loads(result_file.read_text()) if result_file.exists() else {}
    reason = failure.get("error", describe_exit(returncode)).rstrip(".")
    remedy = failure.get("remedy", _RESUME)
    message = f"sweep job {job} died: {reason}. Its run directory: {run_dir}." + (
        f" {remedy}" if remedy else "")
    print(message, flush=True)
    raise SweepJobFailed(message)


def _die_with_parent() -> None:
    """Ask Linux to send this process SIGKILL when its parent (the launcher's worker) dies."""
    if not sys.platform.startswith("linux"):
        return
    parent = os.getppid()
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before the request was in place
        os._exit(1)


def _child(argv: Sequence[str]) -> int:
    job = json.loads(Path(argv[0]).read_text())
    _die_with_parent()
    function = runpy.run_path(job["script"], run_name="sweep_job")[job["function"]]
    try:
        function(OmegaConf.create(job["config"]), set(job["given_keys"]))
    except RunLockedError as locked:
        conflicts = conflicting_values(OmegaConf.create(job["config"]),
                                       locked.holder_config or {}, job["given_keys"])
        if not conflicts:  # a relaunch of this job's own run: the other jobs of the sweep go on
            print(locked.skip_line(), flush=True)
            return _SKIPPED
        return _failed(job, RunConflictError(locked.path, conflicts,
                                             f"the live run writing it ({locked.holder})"), "")
    except RunConflictError as error:  # its message says what to do; a relaunch would not help
        return _failed(job, error, "")
    except BaseException as error:  # noqa: BLE001 (whatever it is, the parent must name it)
        traceback.print_exc()
        return _failed(job, error, _RESUME)
    return 0


def _failed(job: dict[str, Any], error: BaseException, remedy: str) -> int:
    """Leave the parent the error's first line and what to do about it; the child's status."""
    summary = f"{type(error).__name__}: {error}".splitlines()[0]
    Path(job["result"]).write_text(json.dumps({"error": f"raised {summary}", "remedy": remedy}))
    return 1


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1:]))
