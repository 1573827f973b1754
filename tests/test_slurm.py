"""Sweeps through ``hydra/launcher=submitit_slurm`` on a real Slurm cluster: the one-node cluster
``.ci/start_slurm.sh`` starts on this machine (slurmctld + slurmd, Debian's slurm-wlm). Skipped
where no cluster answers.

A two-seed sweep of tiny runs writes both runs; a job cancelled with ``scancel`` in the middle
of its run, and the sweep launched again, resumes the run from its checkpoint and ends with the
episodes of the uninterrupted run of the first sweep, row for row.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import QUICK, RECIPES
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

EPISODES = 30
STEPS = 50  # per episode: long enough that a cancelled job dies mid-run on a fast machine too
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


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    """A two-seed sweep of 30-episode runs, launched once and left alone."""
    root = tmp_path_factory.mktemp("slurm")
    result = launch(root / "sweep", "0,1", root)
    assert result.returncode == 0, result.stderr[-3000:]
    return root / "sweep"


def test_a_two_seed_sweep_writes_both_runs(uninterrupted):
    runs = [RunDirectory(uninterrupted / CONFIGURATION / f"seed{seed}") for seed in (0, 1)]
    jobs = set()
    for seed, run in enumerate(runs):
        summary = run.summary()
        assert summary["episodes"] == EPISODES and summary["env_steps"] == EPISODES * STEPS
        assert summary["config"]["env"]["seed"] == seed
        assert [int(row["episode"]) for row in run.episode_rows()] == list(
            range(1, EPISODES + 1))
        jobs.add(json.loads((run.path / "run.lock.json").read_text())["slurm_job_id"])
    assert None not in jobs and len(jobs) == 2  # each run written by its own Slurm job
    assert runs[0].episode_rows() != runs[1].episode_rows()  # two seeds, two runs
    assert list((uninterrupted / ".submitit").glob("*/*_log.out"))  # submitit's job logs


def test_a_cancelled_job_resumes_from_its_checkpoint_when_the_sweep_is_launched_again(
        uninterrupted, tmp_path):
    sweep = tmp_path / "sweep"
    run = RunDirectory(sweep / CONFIGURATION / "seed0")
    launcher = subprocess.Popen(sweep_command(sweep, "0"), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, cwd=tmp_path)
    try:
        wait_for(run.has_checkpoint, 600, "the job's first checkpoint")
        job = json.loads((run.path / "run.lock.json").read_text())["slurm_job_id"]
        cancelled_at = time.time()
        subprocess.run(["scancel", job], check=True)
        # submitit's job ignores SIGTERM; Slurm kills it KillWait (1 s here) later.
        wait_for(lambda: not in_queue(job) and run.locked_by() is None, 120,
                 f"job {job} to leave the queue")
    finally:
        # Without accounting (no sacct on this cluster) submitit cannot see the job end, so
        # the launching process would wait for it forever.
        launcher.kill()
        launcher.wait()
    done = run.load_checkpoint()["episode"]
    assert 1 <= done < EPISODES, f"the job was not cancelled mid-run ({done} episodes)"
    assert run.summary() is None

    again = launch(sweep, "0", tmp_path)
    assert again.returncode == 0, again.stderr[-3000:]
    assert run.summary()["episodes"] == EPISODES
    # Resumed, not started over: the files from before the cancel are the same files.
    for path in (run.path / "config.json", run.path / "replay" / "000000.pt"):
        assert path.stat().st_mtime < cancelled_at, path
    new_job = json.loads((run.path / "run.lock.json").read_text())["slurm_job_id"]
    assert new_job != job
    reference = uninterrupted / CONFIGURATION / "seed0"
    assert episode_rows(run.path) == episode_rows(reference)
    assert os.listdir(run.path / "replay") and len(os.listdir(run.path / "replay")) == EPISODES
