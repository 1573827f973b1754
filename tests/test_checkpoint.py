"""The checkpoint's schema: every field round-trips through its file, a checkpoint written before
the schema had a version (version 1) still loads, and a file that lacks fields or comes from a
newer version is refused, naming what is wrong; the reports' reader falls back to the previous
checkpoint as a resume does."""

import pytest
import torch
from helpers import make_checkpoint

from temporal_torchrl.runs import CHECKPOINT_VERSION, Checkpoint, RunDirectory


def test_every_field_round_trips(tmp_path):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    written = make_checkpoint(episode=3, env_steps=1500, inserted=53, updates=500,
                              successes=[False, True, True], last_metrics={"sac/alpha": 0.5},
                              credits={"sac": 0.5, "reward": 0.0}, goal_image=torch.ones(4),
                              buffer_capacity=9000, expert_rows=8000, preloaded=50,
                              sac_loss={"w": torch.arange(3.0)})
    run.save_checkpoint(written)
    read = run.load_checkpoint()
    assert read.version == CHECKPOINT_VERSION
    for name, value in written.to_state().items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(getattr(read, name), value), name
        elif name == "sac_loss":
            assert torch.equal(read.sac_loss["w"], value["w"])
        else:
            assert getattr(read, name) == value, name


def test_a_version_1_checkpoint_loads_and_bad_ones_are_named(tmp_path):
    state = make_checkpoint(episode=2).to_state()
    del state["version"], state["credits"]  # as the recipe wrote them before the schema
    checkpoint = Checkpoint.from_state(state, "old.pt")
    assert checkpoint.episode == 2 and checkpoint.credits == {}
    with pytest.raises(ValueError, match=r"old\.pt lacks the checkpoint fields episode, rng"):
        Checkpoint.from_state({k: v for k, v in state.items() if k not in ("episode", "rng")},
                              "old.pt")
    with pytest.raises(ValueError, match="schema version 99; this version of temporal-torchrl "
                                         f"reads up to {CHECKPOINT_VERSION}"):
        Checkpoint.from_state(state | {"version": 99}, "new.pt")


def test_an_unreadable_latest_checkpoint_falls_back_to_the_previous(tmp_path, capsys):
    run = RunDirectory(tmp_path / "run")
    run.create(config={})
    run.save_checkpoint(make_checkpoint(episode=1))
    run.save_checkpoint(make_checkpoint(episode=2))
    run.checkpoint_path.write_bytes(b"cut short by a kill")
    assert run.load_checkpoint().episode == 1
    assert "checkpoint.pt is unreadable" in capsys.readouterr().out
    assert run.checkpoint_path.exists()  # a reader leaves it; only a resume sets it aside
