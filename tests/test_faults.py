"""What clusters do to runs: SIGKILL at random points (in the middle of checkpoint and replay
writes too), a truncated checkpoint, unreadable files, a second writer, a stale lock. Every
interrupted run must end with the episodes of the uninterrupted one.

The killed runs are forked from the test process (real processes, killed with SIGKILL), so a
life costs no interpreter start; test_recipe.py's test_killed_process_resumes kills the command
line itself.
"""

import io
import os
import random
import signal
import socket
import subprocess
import sys
import time
import traceback
from pathlib import Path

import pytest
import sac_temporal
import torch
from helpers import RECIPES, config
from helpers import episode_csv_rows as episode_rows

import temporal_torchrl.runs.durable as durable
from temporal_torchrl.runs import RunDirectory, RunLockedError, UnreadableRunFile, layout

pytestmark = pytest.mark.usefixtures("one_torch_thread")

EPISODES = 12
#: Seed of the kill times (seconds after each life starts): fixed, so a failure reproduces.
KILL_SEED = 21


def slow_writes(marker: Path, seconds: float) -> None:
    """Make every run-directory write pause half-way (the first half flushed), noting in
    ``marker`` the file being written: a kill then leaves it half-written."""
    write_synced = durable.write_synced

    def slow(path, write):
        def in_two_halves(file):
            whole = io.BytesIO()
            write(whole)
            data = whole.getvalue()
            file.write(data[:len(data) // 2])
            file.flush()
            marker.write_text(str(path))
            time.sleep(seconds)
            file.write(data[len(data) // 2:])

        write_synced(path, in_two_halves)
        marker.write_text("")

    durable.write_synced = slow  # every run-directory write goes through it


def fork_run(cfg, marker: Path, log: Path) -> int:
    """Start ``train(cfg)`` in a forked child with slow writes; returns its pid."""
    pid = os.fork()
    if pid == 0:  # the child: never return into pytest
        code = 1
        try:
            slow_writes(marker, seconds=0.15)
            sys.stdout = sys.stderr = log.open("a")
            sac_temporal.train(cfg)
            code = 0
        except BaseException:
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            os._exit(code)
    return pid


def kill(pid: int) -> None:
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)


def wait_for(condition, timeout: float = 60.0) -> None:
    deadline = time.time() + timeout
    while not condition():
        if time.time() > deadline:
            raise TimeoutError("the run did not get there in time")
        time.sleep(0.01)


def test_sigkill_at_random_points_then_resume_gives_the_uninterrupted_episodes(tmp_path):
    """Seven lives of a 12-episode run, each SIGKILLed: one half-way through a checkpoint write,
    one half-way through a replay-episode write, one while it starts (building the model,
    re-inserting the replay), four at random times after an episode more; then a resume to the
    end. episodes.csv, the replay episodes and the networks equal the uninterrupted run's."""
    common = [f"train.episodes={EPISODES}", "train.random_steps=10"]
    reference = sac_temporal.train(config(tmp_path / "reference", *common))
    run = RunDirectory(tmp_path / "killed" / "run")
    marker, log = tmp_path / "writing", tmp_path / "children.log"
    marker.write_text("")
    rng = random.Random(KILL_SEED)

    def checkpointed() -> int:
        return run.load_checkpoint().episode if run.has_checkpoint() else 0

    def life(wait) -> None:
        resume = ["resume=true"] if run.has_checkpoint() else ["overwrite=true"]
        pid = fork_run(config(tmp_path / "killed", *common, *resume), marker, log)
        try:
            wait()
        finally:
            kill(pid)

    def writing(part: str) -> bool:
        return part in marker.read_text() and run.has_checkpoint()

    def an_episode_more_then_random() -> None:
        start = checkpointed()
        wait_for(lambda: checkpointed() > start)
        time.sleep(rng.uniform(0.0, 0.6))

    # Mid-checkpoint: the new checkpoint is half on disk, the old one intact.
    life(lambda: wait_for(lambda: writing(layout.CHECKPOINT + ".tmp")))
    half = run.path / (layout.CHECKPOINT + ".tmp")
    with pytest.raises(Exception):  # noqa: B017 (what torch raises on a cut zip varies)
        torch.load(half, weights_only=True)
    assert torch.load(run.checkpoint_path, weights_only=True)["episode"] >= 1
    life(lambda: wait_for(lambda: writing(f"{layout.REPLAY_DIR}/")))  # mid-replay-episode
    life(lambda: time.sleep(rng.uniform(0.0, 0.5)))  # while it starts
    for _ in range(4):
        life(an_episode_more_then_random)
    done = checkpointed()
    assert 4 <= done < EPISODES, done  # the kills landed across the run, not after its end
    resumed = sac_temporal.train(config(tmp_path / "killed", *common, "resume=true"))

    assert episode_rows(run.path) == episode_rows(tmp_path / "reference" / "run")
    assert resumed["successes"] == reference["successes"]
    assert resumed["env_steps"] == reference["env_steps"] == EPISODES * 20
    final, expected = run.load_checkpoint(), RunDirectory(
        tmp_path / "reference" / "run").load_checkpoint()
    for key, value in expected.sac_loss.items():
        torch.testing.assert_close(final.sac_loss[key], value, msg=key)
    assert sorted(path.name for path in (run.path / "replay").iterdir()) == [
        f"{index:06d}.pt" for index in range(EPISODES)]
    assert "Traceback" not in log.read_text()  # every life died by the kill, none by an error


def test_a_truncated_checkpoint_falls_back_to_the_previous_one(tmp_path, capsys):
    """checkpoint.pt cut to 5,000 bytes (a kill on a filesystem that lost the tail): resume says
    so, continues from checkpoint.previous.pt (one episode earlier), cuts episodes.csv and the
    replay back to it, keeps the cut file aside, and ends with the uninterrupted run's
    episodes."""
    common = ["train.episodes=5"]
    sac_temporal.train(config(tmp_path / "reference", *common))
    sac_temporal.train(config(tmp_path, *common, "train.stop_after_episodes=3"))
    run = RunDirectory(tmp_path / "run")
    with run.checkpoint_path.open("r+b") as file:
        file.truncate(5000)
    capsys.readouterr()
    state = run.resume_state()
    assert (state.episode, state.inserted) == (2, 2)
    assert [row["episode"] for row in run.episode_rows()] == ["1", "2"]
    assert sorted(path.name for path in (run.path / "replay").iterdir()) == [
        "000000.pt", "000001.pt"]
    out = capsys.readouterr().out
    assert "checkpoint.pt is unreadable" in out and "continuing from the previous checkpoint" in out
    assert "(episode 2)" in out
    assert "(the unreadable one is kept as checkpoint.pt.unreadable)" in out
    assert (run.path / "checkpoint.pt.unreadable").stat().st_size == 5000
    summary = sac_temporal.train(config(tmp_path, *common, "resume=true"))
    assert summary["episodes"] == 5
    assert episode_rows(run.path) == episode_rows(tmp_path / "reference" / "run")
    # The cut checkpoint never became the fallback: both checkpoints read, one episode apart.
    assert torch.load(run.previous_checkpoint_path, weights_only=True)["episode"] == 4
    assert run.load_checkpoint().episode == 5


def test_no_readable_checkpoint_is_a_clear_error(tmp_path):
    sac_temporal.train(config(tmp_path, "train.episodes=3", "train.stop_after_episodes=2"))
    run = RunDirectory(tmp_path / "run")
    for path in (run.checkpoint_path, run.previous_checkpoint_path):
        path.write_bytes(path.read_bytes()[:5000])
    with pytest.raises(UnreadableRunFile, match=r"no readable checkpoint in .*checkpoint\.pt is "
                       r"unreadable .*checkpoint\.previous\.pt is unreadable .*overwrite=true"):
        sac_temporal.train(config(tmp_path, "resume=true"))


def test_an_unreadable_episode_row_or_replay_episode_is_named_with_the_fix(tmp_path):
    sac_temporal.train(config(tmp_path, "train.episodes=4", "train.stop_after_episodes=3"))
    run_dir = tmp_path / "run"
    episodes = run_dir / "episodes.csv"
    lines = episodes.read_text().splitlines(keepends=True)
    episodes.write_text("".join([lines[0], lines[1], lines[2][:8] + "\n", *lines[3:]]))
    with pytest.raises(UnreadableRunFile, match=r"episodes\.csv, line 3 .* mean_vlm_reward, "
                       r"stage missing .*episode 2.*Repair that line.*overwrite=true"):
        sac_temporal.train(config(tmp_path, "resume=true"))
    episodes.write_text("".join(lines[:2]))
    with pytest.raises(UnreadableRunFile, match="holds 1 episode rows but the checkpoint covers 3"):
        sac_temporal.train(config(tmp_path, "resume=true"))
    episodes.write_text("".join(lines))
    replay = run_dir / "replay" / "000001.pt"
    replay.write_bytes(replay.read_bytes()[:100])
    with pytest.raises(UnreadableRunFile, match=r"replay episode .*000001\.pt is unreadable.*"
                       r"restore the file from a backup.*overwrite=true"):
        sac_temporal.train(config(tmp_path, "resume=true"))


def test_a_second_process_stops_at_once_and_a_killed_holder_leaves_no_stale_lock(tmp_path):
    run_dir = tmp_path / "run"
    ready, tell = os.pipe()
    holder = os.fork()
    if holder == 0:  # another process holding the run's lock, until it is killed
        try:
            with RunDirectory(run_dir).lock():
                os.write(tell, b"locked")
                time.sleep(600)
        finally:
            os._exit(1)
    try:
        assert os.read(ready, 6) == b"locked"
        started = time.perf_counter()
        with pytest.raises(RunLockedError) as error:
            sac_temporal.train(config(tmp_path))
        assert time.perf_counter() - started < 5  # at once: no waiting on the lock
        message = str(error.value)
        assert f"pid {holder} on host {socket.gethostname()}, since 20" in message
        assert f"stop it (kill {holder} on {socket.gethostname()})" in message
        assert "resume=true" in message and "another output_dir" in message
        assert error.value.path == run_dir
    finally:
        kill(holder)
    # The holder died by SIGKILL: its lock went with it, and its lock files hold no run.
    assert sorted(path.name for path in run_dir.iterdir()) == ["run.lock", "run.lock.json"]
    assert RunDirectory(run_dir).locked_by() is None
    assert sac_temporal.train(config(tmp_path))["episodes"] == 3


def test_a_sweep_job_leaves_a_run_a_live_job_writes_alone(tmp_path):
    """Seed 0's run is locked (as by a job of an earlier launch still running): its job says so
    and ends cleanly, seed 1's runs, and the sweep succeeds."""
    from helpers import QUICK

    sweep = tmp_path / "sweep"
    locked = RunDirectory(sweep / "drawer-open" / "state_furl+d3_rho1_lambda4_generic_stage1"
                          / "seed0")
    with locked.lock():
        result = subprocess.run(
            [sys.executable, str(RECIPES / "sac_temporal.py"), "-m", f"hydra.sweep.dir={sweep}",
             *QUICK, "train.episodes=1", "train.threads=1", "env.seed=0,1"],
            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (f"{locked.path}: skipped, pid {os.getpid()} on host {socket.gethostname()}"
            in result.stdout)
    assert not (locked.path / "config.json").exists()
    seed1 = locked.path.parent / "seed1"
    assert [row["episode"] for row in RunDirectory(seed1).episode_rows()] == ["1"]
