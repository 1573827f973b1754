"""Provenance: each start of a run records the commit, the library versions, the CPU and the torch
threads, checked against git and importlib run here, and no path."""

import json
import subprocess
from importlib import metadata
from pathlib import Path

import sac_temporal
import torch
from helpers import config, make_checkpoint
from test_portable_results import MACHINE_PATH

from temporal_torchrl.runs import RunDirectory
from temporal_torchrl.runs.provenance import (
    PROVENANCE_KEYS,
    TRACKED_DISTRIBUTIONS,
    current_provenance,
)

REPOSITORY = Path(__file__).resolve().parents[1]


def git(*arguments: str) -> str:
    return subprocess.run(["git", *arguments], cwd=REPOSITORY, capture_output=True, text=True,
                          check=True).stdout


def test_an_entry_names_the_commit_the_versions_and_the_machine():
    entry = current_provenance(episode=7)
    assert tuple(entry) == PROVENANCE_KEYS
    assert entry["episode"] == 7
    assert entry["commit"] == git("rev-parse", "HEAD").strip()
    tracked_changes = git("status", "--porcelain", "--untracked-files=no").strip()
    assert entry["clean"] is (tracked_changes == "")
    assert (entry["diff_sha256"] is None) is entry["clean"]
    assert entry["versions"] == {name: metadata.version(name) for name in TRACKED_DISTRIBUTIONS}
    assert entry["torch_threads"] == torch.get_num_threads()
    assert entry["cpu"] and entry["python"].count(".") == 2
    assert not MACHINE_PATH.search(json.dumps(entry))


def test_each_start_is_recorded_and_a_resume_drops_the_starts_it_cuts(tmp_path):
    run = RunDirectory(tmp_path / "run")
    assert run.provenance() == []  # a run from before the file
    run.create(config={})
    for episode in (0, 3, 9):
        run.record_start({"episode": episode, "commit": f"c{episode}"})
    assert [start["commit"] for start in run.provenance()] == ["c0", "c3", "c9"]
    for episode in range(1, 10):
        run.append_episode({"episode": episode, "env_steps": 500 * episode, "success": 0,
                            "return": -500.0, "mean_vlm_reward": 0.0, "stage": 1})
    run.save_checkpoint(make_checkpoint(episode=5))
    run.resume_state()  # the start after episode 9 began after the checkpoint: its work is cut
    assert [start["commit"] for start in run.provenance()] == ["c0", "c3"]


def test_a_run_records_its_start_and_resume_in_its_files(tmp_path):
    cfg = config(tmp_path, "train.episodes=1")
    sac_temporal.train(cfg)
    run = RunDirectory(tmp_path / "run")
    (start,) = run.provenance()
    assert start["episode"] == 0 and start["commit"] == git("rev-parse", "HEAD").strip()
    assert json.loads((run.path / "summary.json").read_text())["provenance"] == [start]

    summary = sac_temporal.train(config(tmp_path, "train.episodes=2", "resume=true"))
    assert [entry["episode"] for entry in summary["provenance"]] == [0, 1]
    assert not MACHINE_PATH.search(json.dumps(summary["provenance"]))
