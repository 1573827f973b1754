"""Run management: the overwrite rules, episode rows cut back to the checkpoint, replay episodes
and RNG states that round-trip, files flushed to disk before they replace the old ones, the
previous checkpoint kept, and the writer's lock."""

import os
import random
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import make_checkpoint, make_episode

import temporal_torchrl.runs.durable as durable
from temporal_torchrl.data import episode_rows
from temporal_torchrl.runs import CHECKPOINT_VERSION, RunDirectory, RunLockedError
from temporal_torchrl.training import MetricWindow, rng_state, set_rng_state

ROW = {"episode": 1, "env_steps": 20, "success": 0, "return": -20.0, "mean_vlm_reward": 0.5,
       "stage": 1}


def test_a_new_directory_starts_and_an_existing_run_is_never_replaced_silently(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.check(resume=False, overwrite=False)  # nothing there: a fresh start
    with pytest.raises(FileNotFoundError, match="start the run without resume=true"):
        run.check(resume=True, overwrite=False)
    run.create(config={"seed": 3})
    run.append_episode(ROW)
    with pytest.raises(FileExistsError, match="overwrite=true"):
        run.check(resume=False, overwrite=False)
    with pytest.raises(FileNotFoundError, match="before its first checkpoint"):
        run.check(resume=True, overwrite=False)
    run.save_checkpoint(make_checkpoint(episode=1))
    with pytest.raises(FileExistsError, match="resume=true to continue it"):
        run.check(resume=False, overwrite=False)
    run.check(resume=True, overwrite=False)
    run.check(resume=False, overwrite=True)
    run.create(config={"seed": 4})  # overwrite: the old run's files are gone
    assert not run.has_checkpoint() and run.episode_rows() == []
    assert run.config() == {"seed": 4}
    assert sorted(path.name for path in run.path.iterdir()) == ["config.json", "replay"]


def test_episode_rows_are_cut_back_to_the_checkpoint(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    for episode in range(1, 5):
        run.append_episode({**ROW, "episode": episode, "env_steps": 20 * episode})
    run.truncate_episodes(2)
    assert [(row["episode"], row["env_steps"]) for row in run.episode_rows()] == [
        ("1", "20"), ("2", "40")]
    run.append_episode({**ROW, "episode": 3, "env_steps": 60})
    assert [row["episode"] for row in run.episode_rows()] == ["1", "2", "3"]
    assert not list(run.path.glob("*.tmp"))


def test_metrics_file_is_json_lines_and_cut_back_to_the_checkpoint(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    run.append_metrics(20, {"train/success": 0.0})
    run.append_metrics(40, {"sac/loss_qvalue": 0.5, "sac/alpha": float("nan")})
    run.append_metrics(60, {"train/success": 1.0})
    assert run.metrics_path.read_text().splitlines() == [
        '{"step": 20, "train/success": 0.0}',
        '{"step": 40, "sac/loss_qvalue": 0.5, "sac/alpha": null}',
        '{"step": 60, "train/success": 1.0}']
    run.truncate_metrics(40)  # resume from a checkpoint at env step 40
    run.append_metrics(60, {"train/success": 0.0})
    assert run.metric_points() == [{"step": 20, "train/success": 0.0},
                                   {"step": 40, "sac/loss_qvalue": 0.5, "sac/alpha": None},
                                   {"step": 60, "train/success": 0.0}]
    assert not list(run.path.glob("*.tmp"))
    with pytest.raises(ValueError, match="clashes"):
        run.append_metrics(80, {"step": 1.0})


def test_metrics_file_skips_a_cut_last_line_and_names_a_bad_one(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    run.append_metrics(20, {"train/success": 0.0})
    with run.metrics_path.open("a") as file:
        file.write('{"step": 40, "train/succ')  # killed mid-write
    assert [point["step"] for point in run.metric_points()] == [20]
    run.truncate_metrics(20)  # the resume drops the cut line
    assert run.metrics_path.read_text() == '{"step": 20, "train/success": 0.0}\n'
    for bad, match in (('{"step": 40, "x"\n', "is not JSON"),
                       ('{"step": "40", "x": 1}\n', 'integer "step"'),
                       ('{"step": 40, "x": "high"}\n', "numbers")):
        run.metrics_path.write_text(bad + '{"step": 60}\n')
        with pytest.raises(ValueError, match=match) as error:
            run.metric_points()
        assert "metrics.jsonl:1" in str(error.value)


def test_replay_episodes_and_checkpoint_round_trip(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    saved = [episode_rows(make_episode(index, 5 + index)) for index in range(3)]
    for index, rows in enumerate(saved):
        run.save_replay_episode(index, rows)
    loaded = list(run.replay_episodes(2))
    assert len(loaded) == 2
    for original, restored in zip(saved, loaded, strict=False):
        assert restored.shape == original.shape
        assert (restored == original).all()
        assert restored["embedding"].dtype == torch.float16
    run.save_checkpoint(make_checkpoint(episode=7, successes=[False, True],
                                        sac_loss={"weights": torch.arange(4.0)}))
    restored = run.load_checkpoint()
    assert restored.episode == 7 and restored.successes == [False, True]
    assert torch.equal(restored.sac_loss["weights"], torch.arange(4.0))
    assert restored.version == CHECKPOINT_VERSION
    assert not list(run.path.rglob("*.tmp"))


def test_rng_state_restores_every_generator(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    torch.manual_seed(1), random.seed(2), np.random.seed(3)
    run.save_checkpoint(make_checkpoint(rng=rng_state()))
    expected = (torch.rand(3), random.random(), np.random.rand(2))
    torch.manual_seed(9), random.seed(9), np.random.seed(9)
    set_rng_state(run.load_checkpoint().rng)
    assert torch.equal(torch.rand(3), expected[0])
    assert random.random() == expected[1]
    assert np.array_equal(np.random.rand(2), expected[2])


def test_files_reach_the_disk_before_they_replace_the_old_ones(tmp_path, monkeypatch):
    """The order of a checkpoint write: the new file fsync'd, the old checkpoint renamed to the
    previous one, the new one renamed in, the directory fsync'd; a replay episode and a JSON
    file likewise (fsync, rename, directory fsync)."""
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    run.save_checkpoint(make_checkpoint(episode=1))
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(durable.os, "fsync", lambda fd: (
        events.append(("fsync", Path(os.readlink(f"/proc/self/fd/{fd}")).name)), real_fsync(fd)))
    monkeypatch.setattr(durable.os, "replace", lambda source, target: (
        events.append(("replace", Path(source).name, Path(target).name)),
        real_replace(source, target)))
    run.save_checkpoint(make_checkpoint(episode=2))
    assert events == [("fsync", "checkpoint.pt.tmp"),
                      ("replace", "checkpoint.pt", "checkpoint.previous.pt"),
                      ("replace", "checkpoint.pt.tmp", "checkpoint.pt"), ("fsync", "run")]
    assert run.load_checkpoint().episode == 2
    assert torch.load(run.previous_checkpoint_path, weights_only=True)["episode"] == 1
    events.clear()
    run.save_replay_episode(0, episode_rows(make_episode(0, 3)))
    run.write_summary({"episodes": 2})
    assert events == [("fsync", "000000.pt.tmp"), ("replace", "000000.pt.tmp", "000000.pt"),
                      ("fsync", "replay"), ("fsync", "summary.json.tmp"),
                      ("replace", "summary.json.tmp", "summary.json"), ("fsync", "run")]
    events.clear()
    run.append_episode(ROW)
    assert events == [("fsync", "episodes.csv"), ("fsync", "run")]  # a new file: its entry too


def test_a_kill_between_the_checkpoint_renames_resumes_from_the_previous_one(tmp_path, capsys):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    run.save_checkpoint(make_checkpoint(episode=1, inserted=1))
    run.save_checkpoint(make_checkpoint(episode=2, inserted=2))
    run.checkpoint_path.rename(run.path / "checkpoint.pt.tmp")  # as left by a kill there
    assert run.has_checkpoint()
    run.check(resume=True, overwrite=False)
    assert run.load_checkpoint().episode == 1
    assert ("checkpoint.pt does not exist; continuing from the previous checkpoint"
            in capsys.readouterr().out)


def test_the_lock_is_held_for_the_block_and_never_blocks_after_it(tmp_path):
    run = RunDirectory(tmp_path / "run")
    with run.lock():
        assert "pid" in run.locked_by()  # this process holds it, through another descriptor
        with pytest.raises(RunLockedError, match=f"pid {os.getpid()} on host"), run.lock():
            pass
        run.check(resume=False, overwrite=False)  # the lock's files are not a run
        run.create(config={"seed": 1})
        assert sorted(path.name for path in run.path.iterdir()) == [
            "config.json", "replay", "run.lock", "run.lock.json"]
        run.create(config={"seed": 2})  # overwrite keeps the lock it holds
        assert (run.path / "run.lock").exists()
    assert run.locked_by() is None
    with run.lock():  # free again
        assert run.config() == {"seed": 2}
    # A directory the lock made and nothing else used is removed again (a run that never began).
    unused = RunDirectory(tmp_path / "unused")
    with pytest.raises(FileNotFoundError, match="start the run without resume=true"):
        with unused.lock():
            unused.check(resume=True, overwrite=False)
    assert not unused.path.exists()


def test_a_short_window_is_pending_until_flushed():
    from tensordict import TensorDict

    window = MetricWindow()
    assert not window.pending
    window.add("sac", TensorDict({"alpha": torch.tensor(0.5)}, []))
    assert window.pending
    assert window.flush() == {"sac/alpha": 0.5} and not window.pending


def test_a_forked_worker_does_not_keep_a_killed_runs_lock(tmp_path):
    """A run's env workers may be forked (ParallelEnv) and outlive a SIGKILLed run: the lock
    still goes with the run, so the resume is not blocked by an orphan."""
    import signal
    import time

    run = RunDirectory(tmp_path / "run")
    ready, tell = os.pipe()
    runner = os.fork()
    if runner == 0:
        try:
            with run.lock():
                worker = os.fork()
                if worker == 0:
                    time.sleep(60)
                    os._exit(0)
                os.write(tell, str(worker).encode())
                time.sleep(60)
        finally:
            os._exit(1)
    worker = int(os.read(ready, 20))
    try:
        assert run.locked_by() is not None
        os.kill(runner, signal.SIGKILL)
        os.waitpid(runner, 0)
        assert Path(f"/proc/{worker}").exists()  # the orphaned worker lives on
        assert run.locked_by() is None
    finally:
        os.kill(worker, signal.SIGKILL)
