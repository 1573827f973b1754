"""Sweeps through ``hydra/launcher=submitit_slurm`` on a real Slurm cluster: the one-node cluster
``.ci/start_slurm.sh`` starts on this machine (slurmctld + slurmd, Debian's slurm-wlm). Skipped
where no cluster answers.

A two-seed sweep of tiny runs, one of whose jobs is cancelled with ``scancel`` in the middle of
its run: launched again, the sweep resumes that run from its checkpoint, leaves the finished one
as it is, and both end with the episodes of uninterrupted runs, row for row (one run in this
process is the reference: one sweep launch less, about a minute of the suite).
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import sac_temporal
from helpers import QUICK, RECIPES, config
from helpers import episode_csv_rows as episode_rows

from temporal_torchrl.runs import RunDirectory


def _no_cluster() -> str | None:
    """Why no Slurm test can run here, None when a cluster with a usable node answers."""
    if shutil.which("sbatch") is None:
        return "no Slurm here (no sbatch): .ci/start_slurm.sh installs and starts a one-node one"
    try:
        states = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True,
                                timeout=20).stdout.split()
    except subprocess.TimeoutExpired:
        return "sinfo timed out: no slurmctld answers (start one with .ci/start_slurm.sh)"
    if not any(state in ("idle", "mix", "alloc") for state in states):
        return f"no Slurm node is up (sinfo: {states or 'nothing'}); see .ci/start_slurm.sh"
    return None


pytestmark = [pytest.mark.slurm,
              pytest.mark.skipif(_no_cluster() is not None, reason=str(_no_cluster()))]

EPISODES = 15  # the cancel follows the first checkpoint (episode 1): it lands well before 15
STEPS = 20  # per episode (the cancel is a SIGKILL: it lands mid-run however short they are)
#: The recipe tests' tiny run, but for its length.
TINY = [override for override in QUICK
        if not override.startswith(("env.max_episode_steps=", "train.episodes="))]
CONFIGURATION = "drawer-open/state_furl+d3_rho1_lambda4_generic_stage1"


def sweep_command(sweep: Path, seeds: str) -> list[str]:
    return [sys.executable, str(RECIPES / "sac_temporal.py"), "-m",
            "hydra/launcher=submitit_slurm", f"hydra.sweep.dir={sweep}",
            "hydra.launcher.timeout_min=15", "hydra.launcher.cpus_per_task=1",
            "hydra.launcher.mem_gb=2", *TINY, f"env.max_episode_steps={STEPS}",
            f"train.episodes={EPISODES}",
            "train.threads=1", f"env.seed={seeds}"]


def launch(sweep: Path, seeds: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(sweep_command(sweep, seeds), capture_output=True, text=True,
                          timeout=900, cwd=cwd)


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.time() + timeout
    while not condition():
        if time.time() > deadline:
            raise TimeoutError(f"waited {timeout:.0f} s for {what}")
        time.sleep(0.2)


def in_queue(job: str) -> bool:
    return bool(subprocess.run(["squeue", "-h", "-j", job], capture_output=True,
                               text=True).stdout.strip())


def test_a_sweep_with_a_cancelled_job_resumes_it_when_launched_again(tmp_path):
    sweep = tmp_path / "sweep"
    runs = [RunDirectory(sweep / CONFIGURATION / f"seed{seed}") for seed in (0, 1)]
    launcher = subprocess.Popen(sweep_command(sweep, "0,1"), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, cwd=tmp_path)
    try:
        wait_for(runs[0].has_checkpoint, 600, "seed 0's first checkpoint")
        job = json.loads((runs[0].path / "run.lock.json").read_text())["slurm_job_id"]
        cancelled_at = time.time()
        # At once, as a pre-empted job dies: submitit's job would ignore scancel's SIGTERM until
        # KillWait, while these tiny episodes take a fraction of a second each. The KILL goes to
        # the run's step (JOB.0) first: sent to the whole job, it reached the batch shell and
        # srun, and the run itself lived on for about 7 s, as long as these runs take on a
        # quiet machine (it then finished before the cancel landed). Then the job is cancelled.
        subprocess.run(["scancel", "--signal=KILL", f"{job}.0"], check=True)
        subprocess.run(["scancel", job], check=True)
        wait_for(lambda: not in_queue(job) and runs[0].locked_by() is None, 120,
                 f"job {job} to leave the queue")
        wait_for(lambda: runs[1].summary() is not None, 600, "seed 1's job to finish")
    finally:
        # Without accounting (no sacct on this cluster) submitit cannot see the cancelled job
        # end, so the launching process would wait for it forever.
        launcher.kill()
        launcher.wait()
    done = runs[0].load_checkpoint().episode
    assert 1 <= done < EPISODES, f"the job was not cancelled mid-run ({done} episodes)"
    assert runs[0].summary() is None
    finished_at = (runs[1].path / "summary.json").stat().st_mtime

    again = launch(sweep, "0,1", tmp_path)
    assert again.returncode == 0, again.stderr[-3000:]
    jobs = set()
    for seed, run in enumerate(runs):
        summary = run.summary()
        assert summary["episodes"] == EPISODES and summary["env_steps"] == EPISODES * STEPS
        assert summary["config"]["env"]["seed"] == seed
        jobs.add(json.loads((run.path / "run.lock.json").read_text())["slurm_job_id"])
    assert None not in jobs and len(jobs) == 2 and job not in jobs  # a job of its own each
    assert list((sweep / ".submitit").glob("*/*_log.out"))  # submitit's job logs
    # Resumed, not started over; the finished run left as it was.
    for path in (runs[0].path / "config.json", runs[0].path / "replay" / "000000.pt"):
        assert path.stat().st_mtime < cancelled_at, path
    assert (runs[1].path / "summary.json").stat().st_mtime == finished_at
    assert len(os.listdir(runs[0].path / "replay")) == EPISODES
    # Both as the uninterrupted run of the same settings: the cancelled one included.
    reference = tmp_path / "reference"
    sac_temporal.train(config(reference, f"env.max_episode_steps={STEPS}",
                              f"train.episodes={EPISODES}", "env.seed=0"))
    assert episode_rows(runs[0].path) == episode_rows(reference / "run")
    assert episode_rows(runs[1].path) != episode_rows(runs[0].path)  # two seeds, two runs
