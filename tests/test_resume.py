"""Resuming a run: what clusters do to runs (SIGKILL at random points, in the middle of
checkpoint and replay writes too; a truncated checkpoint; unreadable files; a second writer; a
stale lock), then resume as a user asks for it (the saved config, the resumable keys, an
extended run, a killed command line). Every interrupted run must end with the episodes of the
uninterrupted one.

The killed runs of the first part are forked from the test process (real processes, killed
with SIGKILL), so a life costs no interpreter start; test_killed_process_resumes kills the
command line itself. Feature-specific resumes (several envs, relay, beyond-thesis rewards,
sweeps) sit beside their features' tests; the checkpoint's format in test_checkpoint.py.
"""

import io
import json
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
from helpers import QUICK, RECIPES, config
from helpers import episode_csv_rows as episode_rows
from omegaconf import OmegaConf
from torchrl.modules import MLP, ValueOperator

import temporal_torchrl.runs.durable as durable
from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.runs import (
    RunConflictError,
    RunDirectory,
    RunLockedError,
    UnreadableRunFile,
    layout,
    override_keys,
    resumed_config,
)
from temporal_torchrl.training import factories

# ---- faults: kills, truncated and unreadable files, a second writer

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


@pytest.mark.slow
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


@pytest.mark.slow
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


# ---- resume from the command line and from the config


def test_kill_and_resume_continues_the_run(tmp_path):
    sac_temporal.train(config(tmp_path, "train.episodes=4", "train.stop_after_episodes=2"))
    run_dir = tmp_path / "run"
    assert len(episode_rows(run_dir)) == 2 and not (run_dir / "summary.json").exists()
    # a killed run leaves an episode row the checkpoint may not cover: it is dropped on resume
    RunDirectory(run_dir).append_episode({"episode": 3, "env_steps": 999, "success": 0,
                                       "return": 0.0, "mean_vlm_reward": 0.0, "stage": 1})
    RunDirectory(run_dir).append_metrics(999, {"train/success": 0.0})  # and a metrics point
    with pytest.raises(FileExistsError, match="resume=true"):
        sac_temporal.train(config(tmp_path, "train.episodes=4"))
    summary = sac_temporal.train(config(tmp_path, "train.episodes=4", "resume=true"))
    rows = episode_rows(run_dir)
    assert [int(row["episode"]) for row in rows] == [1, 2, 3, 4]
    assert [int(row["env_steps"]) for row in rows] == [20, 40, 60, 80]
    # metrics.jsonl with logger.backend=none: the episode points once each, the last (partial)
    # window of training metrics, then the summary
    points = RunDirectory(run_dir).metric_points()
    assert [point["step"] for point in points] == [20, 40, 60, 80, 80, 80]
    assert [point["train/success"] for point in points[:4]] == [
        float(row["success"]) for row in rows]
    assert "sac/loss_qvalue" in points[4]
    assert set(points[5]) == {"step", "summary/ttfs", "summary/tt50s"}
    assert summary["episodes"] == 4 and summary["env_steps"] == 80
    assert RunDirectory(run_dir).load_checkpoint().inserted == 4


def test_a_checkpoint_of_torchrls_sac_loss_is_refused_with_the_way_out(tmp_path):
    """A run checkpointed by the version that trained with TorchRL's SACLoss (critics as
    functional parameters) cannot resume here: the error names the version that can."""
    from torchrl.objectives import SACLoss

    sac_temporal.train(config(tmp_path, "train.episodes=2", "train.stop_after_episodes=1"))
    run = RunDirectory(tmp_path / "run")
    checkpoint = run.load_checkpoint()
    cfg = config(tmp_path)
    env = factories.make_environment(cfg, None, None)
    actor, _ = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    env.close()
    qvalue = ValueOperator(MLP(in_features=43, num_cells=[256, 256], out_features=1),
                           in_keys=["action", "observation"])
    checkpoint.sac_loss = SACLoss(actor, qvalue, num_qvalue_nets=2,
                                     target_entropy=-2.0).state_dict()
    run.save_checkpoint(checkpoint)
    with pytest.raises(ValueError, match="Resume the run with the release that wrote it"):
        sac_temporal.train(config(tmp_path, "train.episodes=2", "resume=true"))


def test_resume_continues_with_the_saved_config(tmp_path, capsys):
    sac_temporal.train(config(tmp_path, "env.task=door-open", "reward.rho=0.05",
                              "train.episodes=2", "train.stop_after_episodes=1"))
    # A run started before a config key existed resumes with the key's current default.
    saved_config = tmp_path / "run" / "config.json"
    saved = json.loads(saved_config.read_text())
    del saved["train"]["expert_steps_after_success"]
    saved_config.write_text(json.dumps(saved))
    # Only the run directory and resume=true are restated; the defaults name another task.
    summary = sac_temporal.train(config(tmp_path, "resume=true", "train.episodes=2"))
    assert summary["config"]["env"]["task"] == "door-open"
    assert summary["config"]["reward"]["rho"] == 0.05
    assert summary["ras"]["budget"] == 400  # door-open's, not drawer-open's 300
    assert summary["config"]["train"]["expert_steps_after_success"] is None
    assert "not using the current values of env.task" in capsys.readouterr().out


def test_a_run_saved_with_the_deprecated_reward_keys_resumes_as_it_was(tmp_path):
    """Runs saved before d_sequence's and d_certainty's hyperparameters became reward options
    hold reward.window, reward.certainty_bandwidth and reward.certainty_prior in config.json
    (at 8, 0.1 and 1.0 unless changed) and no reward.options. At the defaults such a run
    resumes in the directory its name had, without a warning, even when the command line
    restates a key; a changed key resumes as its option, with a FutureWarning naming it."""
    import warnings

    def saved_as_before(run_dir: Path, window: int) -> None:
        saved_config = run_dir / "config.json"
        saved = json.loads(saved_config.read_text())
        assert saved["reward"]["window"] is None  # this version writes the options
        saved["reward"].update(window=window, certainty_bandwidth=0.1, certainty_prior=1.0)
        del saved["reward"]["options"]
        saved_config.write_text(json.dumps(saved))

    common = ["reward.directional=d_sequence", "train.episodes=2", "output_dir=null",
              f"runs_dir={tmp_path}"]
    sac_temporal.train(config(tmp_path, *common, "train.stop_after_episodes=1"))
    run_dir = tmp_path / "drawer-open" / "state_furl+d_sequence_rho1_lambda4_generic_stage1"
    saved_as_before(run_dir / "seed0", window=8)
    overrides = [*common, "resume=true", "reward.window=8"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", FutureWarning)
        summary = sac_temporal.train(config(tmp_path, *overrides), override_keys(overrides))
    assert summary["episodes"] == 2 and summary["config"]["reward"]["options"] == {}
    assert len(episode_rows(run_dir / "seed0")) == 2
    assert [path.name for path in tmp_path.iterdir()] == ["drawer-open"]
    assert [path.name for path in run_dir.parent.iterdir()] == [run_dir.name]

    # A run of a 4-embedding window: its heads (a 3-token encoder) load again only if it is.
    sac_temporal.train(config(tmp_path, "reward.directional=d_sequence", "train.episodes=2",
                              "+reward.options.window=4", "train.stop_after_episodes=1"))
    saved_as_before(tmp_path / "run", window=4)
    with pytest.warns(FutureWarning, match=r"config reward\.window=4 is deprecated and read as "
                                           r"reward\.options\.window=4"):
        summary = sac_temporal.train(config(tmp_path, "resume=true", "train.episodes=2"))
    assert summary["episodes"] == 2 and summary["config"]["reward"]["options"] == {"window": 4}


def test_a_run_of_another_config_in_its_directory_is_refused(tmp_path):
    # A sweep over a key the directory's name does not tell apart (sac.lr) maps its jobs to one
    # directory: the second job must fail, naming the key, not continue the first job's run.
    sac_temporal.train(config(tmp_path, "sac.lr=0.0001", "train.episodes=1"))
    run_dir = tmp_path / "run"
    finished = {name: (run_dir / name).read_bytes() for name in ("episodes.csv", "summary.json")}
    for resume in ("true", "false"):
        overrides = ["sac.lr=0.0003", f"resume={resume}"]
        with pytest.raises(RunConflictError, match=(
                r"asks for sac.lr=0.0003, the run there has sac.lr=0.0001\..*not by sac.lr.*"
                r"output_dir='\$\{hydra:sweep.dir\}/\$\{env.task\}_lr\$\{sac.lr\}/")):
            sac_temporal.train(config(tmp_path, *overrides, "train.episodes=1"),
                               override_keys(overrides))
    assert {name: (run_dir / name).read_bytes() for name in finished} == finished
    # What one run may change between its processes is no conflict, nor is a key not given.
    overrides = ["resume=true", "train.device=cpu", "logger.backend=csv", "train.episodes=1"]
    summary = sac_temporal.train(config(tmp_path, *overrides, "sac.lr=0.0003"),
                                 override_keys(overrides))
    assert summary["config"]["sac"]["lr"] == 0.0001
    # overwrite=true replaces the run, as asked.
    overrides = ["sac.lr=0.0003", "overwrite=true", "train.episodes=1"]
    summary = sac_temporal.train(config(tmp_path, *overrides), override_keys(overrides))
    assert summary["config"]["sac"]["lr"] == 0.0003


def test_a_sweep_job_meeting_another_configs_live_run_fails_and_names_it(tmp_path):
    # Two jobs of one parallel sweep on one directory: the second finds the first's lock. The
    # lock keeps the holder's config, so the job fails instead of skipping as it does for a
    # relaunch of its own run (the same config).
    from temporal_torchrl.runs.sweep_job import SweepJobFailed, run_sweep_job

    holder, job = (config(tmp_path, f"sac.lr={lr}") for lr in ("0.0001", "0.0003"))
    run = RunDirectory(tmp_path / "run")
    with run.lock(config=OmegaConf.to_container(holder, resolve=True)):
        with pytest.raises(SweepJobFailed) as failure:
            run_sweep_job(RECIPES / "sac_temporal.py", "run", job, {"sac.lr"}, "#1", run.path)
    message = str(failure.value)
    assert "raised RunConflictError" in message and "the live run writing it (pid" in message
    assert "sac.lr=0.0003, the live run writing it" in message and "Launch the same" not in message


def test_resume_changes_only_the_resumable_keys_given(tmp_path, capsys):
    sac_temporal.train(config(tmp_path, "train.episodes=6", "train.stop_after_episodes=1"))
    run_dir = tmp_path / "run"
    # On the command line: `resume=true output_dir=...` restates neither value.
    cfg = config(tmp_path, "resume=true", "train.episodes=3", "train.checkpoint_every=2")
    resumed = resumed_config(cfg, run_dir, override_keys(
        ["resume=true", f"output_dir={run_dir}", "+train.checkpoint_every=2"]))
    assert resumed.train.episodes == 6 and resumed.train.checkpoint_every == 2
    assert resumed.resume and resumed.train.stop_after_episodes is None
    assert "not using the current values of train.episodes" in capsys.readouterr().out
    # A config built in code means all of its values.
    assert resumed_config(cfg, run_dir).train.episodes == 3


def test_resume_validates_the_config_it_runs(tmp_path):
    sac_temporal.train(config(tmp_path, "train.stop_after_episodes=1"))
    saved_config = tmp_path / "run" / "config.json"
    saved = json.loads(saved_config.read_text())
    saved["reward"]["rho"] = -1.0
    saved_config.write_text(json.dumps(saved))
    with pytest.raises(ValueError, match=r"reward\.rho=-1\.0"):
        sac_temporal.train(config(tmp_path, "resume=true"))

    saved["reward"]["rho"] = 1.0
    saved["train"]["epsiodes"] = 3  # a key this version does not read (an old or edited file)
    saved_config.write_text(json.dumps(saved))
    with pytest.raises(ValueError) as error:
        sac_temporal.train(config(tmp_path, "resume=true"))
    message = str(error.value)
    assert message.startswith("config key 'train.epsiodes' is not declared in section 'train'")
    assert f"The run's saved {saved_config}" in message
    assert "remove the key from that file to resume it with this version" in message


def test_extended_run_grows_the_buffer_and_keeps_the_experts(tmp_path, capsys):
    """Resuming with more episodes grows a whole-run buffer; with a fixed capacity the ring
    wraps but never overwrites the preloaded experts."""
    run_dir = tmp_path / "run"
    stage2 = ["protocol=stage2", "train.preload_positives=1", "train.random_steps=5"]
    sac_temporal.train(config(tmp_path, *stage2, "train.episodes=2"))
    expert_rows = RunDirectory(run_dir).load_checkpoint().expert_rows
    assert RunDirectory(run_dir).load_checkpoint().buffer_capacity == 2 * 21 + expert_rows
    summary = sac_temporal.train(config(tmp_path, "resume=true", "train.episodes=5"))
    assert summary["episodes"] == 5
    assert RunDirectory(run_dir).load_checkpoint().buffer_capacity == 5 * 21 + expert_rows
    assert f"replay capacity grown from {2 * 21 + expert_rows} to {5 * 21 + expert_rows}" in (
        capsys.readouterr().out)

    small = config(tmp_path, *stage2, "train.episodes=6", "overwrite=true",
                   f"replay_buffer.capacity={expert_rows + 2 * 21}")
    sac_temporal.train(small)
    state = RunDirectory(run_dir).load_checkpoint()
    buffer = factories.make_replay_buffer(small, state.buffer_capacity, reward=None,
                                          devices=Devices.of(small))
    for rows in RunDirectory(run_dir).replay_episodes(state.inserted):
        buffer.extend(rows)
    stored = set().union(*(buffer.sample()["episode"].tolist() for _ in range(60)))
    assert stored == {0, 5, 6}  # the expert and the last two training episodes
    assert buffer.stage == 2


def test_run_stopped_before_its_first_checkpoint_is_replaced_not_resumed(tmp_path):
    (tmp_path / "run" / "replay").mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match="overwrite=true instead of resume=true"):
        sac_temporal.train(config(tmp_path, "resume=true"))
    with pytest.raises(FileExistsError, match="holds no checkpoint.pt") as error:
        sac_temporal.train(config(tmp_path))
    assert "resume=true" not in str(error.value)
    assert sac_temporal.train(config(tmp_path, "overwrite=true"))["episodes"] == 3


@pytest.mark.slow
def test_killed_process_resumes(tmp_path):
    """A real SIGKILL in the middle of an episode, then the README's resume=true in a new
    process (a second process on a live run: the second-process test above)."""
    run_dir = tmp_path / "run"
    args = [sys.executable, str(RECIPES / "sac_temporal.py"), *QUICK, f"output_dir={run_dir}",
            "train.threads=1"]
    process = subprocess.Popen([*args, "train.episodes=1000"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    # An episode's row is written just before its checkpoint: the third row means the second
    # episode's checkpoint is on disk.
    deadline = time.time() + 120
    while not (run_dir / "episodes.csv").exists() or len(episode_rows(run_dir)) < 3:
        assert process.poll() is None, f"the run ended early (status {process.returncode})"
        assert time.time() < deadline, "the run wrote no third episode row within 120 s"
        time.sleep(0.05)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    done = RunDirectory(run_dir).load_checkpoint().episode
    assert done >= 2
    # The README's command: nothing restated, so the run keeps its own 1,000 episodes (here it
    # is stopped one episode later, as if killed again, without writing a summary).
    resumed = subprocess.run([sys.executable, str(RECIPES / "sac_temporal.py"),
                              f"output_dir={run_dir}", "resume=true",
                              f"train.stop_after_episodes={done + 1}", "train.progress=false"],
                             capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert f"resumed: after episode {done:,} of 1,000 ({20 * done:,} env steps" in resumed.stdout
    assert not (run_dir / "summary.json").exists()
    # A train.episodes given on the command line ends the run there.
    finished = subprocess.run([*args, f"train.episodes={done + 2}", "resume=true"],
                              capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr[-2000:]
    rows = episode_rows(run_dir)
    assert [int(row["episode"]) for row in rows] == list(range(1, done + 3))
    assert [int(row["env_steps"]) for row in rows] == [20 * i for i in range(1, done + 3)]
    assert json.loads((run_dir / "summary.json").read_text())["episodes"] == done + 2
