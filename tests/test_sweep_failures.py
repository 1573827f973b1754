"""A sweep job that dies says so: a real two-job joblib sweep in which one job raises in the middle
of its run and the other is killed from outside with SIGKILL. The sweep names each job, its run
directory and the exception or signal, goes on to the end and exits non-zero; launched again, it
resumes both runs from their checkpoints to the episodes they were asked for."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import QUICK, RECIPES, episode_csv_rows

from temporal_torchrl.runs.sweep_job import describe_exit

# Imported by each job's training process (reward.modules): after episode 2, while the marker
# file exists, the seed-0 run raises and the seed-1 run writes its pid and waits to be killed.
FAULTS = '''
import os, time
from pathlib import Path
from temporal_torchrl.runs.directory import RunDirectory

MARKER = Path({marker!r})
_append_episode = RunDirectory.append_episode


def append_episode(self, row):
    _append_episode(self, row)
    if row["episode"] != 2 or not MARKER.exists():
        return
    if self.path.name == "seed0":
        raise RuntimeError("injected fault after episode 2")
    (MARKER.parent / "pid").write_text(str(os.getpid()))
    time.sleep(600)


RunDirectory.append_episode = append_episode
'''


def sweep(tmp_path: Path, faults: Path) -> subprocess.Popen:
    command = [sys.executable, str(RECIPES / "sac_temporal.py"), "-m", "hydra/launcher=joblib",
               "hydra.launcher.n_jobs=2", f"hydra.sweep.dir={tmp_path / 'sweep'}",
               "preset=sac", *QUICK, "train.episodes=4", f"reward.modules=[{faults}]",
               "env.seed=0,1"]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=os.environ | {"PYTHONUNBUFFERED": "1"})


def wait_for(path: Path, process: subprocess.Popen, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        if process.poll() is not None:
            raise AssertionError(f"the sweep ended before {path} was written:\n"
                                 f"{process.stdout.read()}")
        if time.monotonic() > deadline:
            process.kill()
            raise AssertionError(f"{path} not written within {seconds} s:\n{process.stdout.read()}")
        time.sleep(0.2)


@pytest.mark.slow
def test_dead_jobs_are_named_and_a_relaunch_resumes_them(tmp_path):
    marker, faults = tmp_path / "faults_on", tmp_path / "faults.py"
    marker.touch()
    faults.write_text(FAULTS.format(marker=str(marker)))
    runs = tmp_path / "sweep" / "drawer-open" / "sac_stage1"

    process = sweep(tmp_path, faults)
    wait_for(tmp_path / "pid", process, seconds=240)  # seed 1 recorded episode 2 and waits
    os.kill(int((tmp_path / "pid").read_text()), signal.SIGKILL)
    output, _ = process.communicate(timeout=120)
    assert process.returncode != 0, output
    assert (f"died: raised RuntimeError: injected fault after episode 2. Its run directory: "
            f"{runs / 'seed0'}") in output, output
    assert "died: killed by SIGKILL (kill -9, the kernel's OOM killer" in output, output
    assert f"Its run directory: {runs / 'seed1'}" in output, output
    for seed in (0, 1):  # both stopped after episode 2, checkpointed after episode 1
        assert json.loads((runs / f"seed{seed}" / "config.json").read_text())["env"]["seed"] == seed
        assert not (runs / f"seed{seed}" / "summary.json").exists()

    marker.unlink()
    process = sweep(tmp_path, faults)
    output, _ = process.communicate(timeout=300)
    assert process.returncode == 0, output
    assert "RuntimeWarning" not in output, output  # e.g. runpy's, were the job's module imported
    for seed in (0, 1):
        rows = episode_csv_rows(runs / f"seed{seed}")
        assert [int(row["episode"]) for row in rows] == [1, 2, 3, 4]
        assert json.loads((runs / f"seed{seed}" / "summary.json").read_text())["episodes"] == 4


def test_exit_statuses_are_described():
    assert describe_exit(-signal.SIGKILL).startswith("killed by SIGKILL (kill -9")
    assert describe_exit(-signal.SIGSEGV) == ("killed by SIGSEGV (a segmentation fault in "
                                              "native code)")
    assert describe_exit(-signal.SIGUSR1) == "killed by SIGUSR1"
    assert describe_exit(2) == "exited with status 2"
