"""Committed results are portable: a study's raw files are collected without checkpoints, replay
or machine paths, reports write run paths relative to the folder they were given, and no
committed results file names a machine's folders."""

import re
from pathlib import Path

import yaml

from temporal_torchrl.reports.tables import relative_run_path
from temporal_torchrl.runs.collect import collect_study

REPOSITORY = Path(__file__).resolve().parents[1]
#: Absolute paths of the kinds machines have (POSIX home, scratch and temporary folders).
MACHINE_PATH = re.compile(r"(?<![\w.~-])/(?:work|home|tmp|root|Users|mnt|scratch|private|var)/")


def make_run(run: Path, finished: bool, evaluated: bool = False) -> None:
    (run / "logs" / "seed0" / "scalars").mkdir(parents=True)
    (run / "replay").mkdir()
    (run / "replay" / "000000.pt").write_bytes(b"replay")
    (run / "checkpoint.pt").write_bytes(b"checkpoint")
    (run / "config.json").write_text("{}")
    (run / "episodes.csv").write_text("episode\n1\n")
    (run / "metrics.jsonl").write_text("{}\n")
    (run / "provenance.json").write_text('{"starts": []}')
    (run / "logs" / "seed0" / "scalars" / "loss.csv").write_text("1,2\n")
    if finished:
        (run / "summary.json").write_text("{}")
    if evaluated:
        (run / "eval.csv").write_text("episode,env_steps\n10,5000\n")


def test_collect_copies_finished_runs_raw_files_only(tmp_path):
    sweep = tmp_path / "machine" / "sweeps" / "study"
    make_run(sweep / "window-close" / "sac_stage2" / "seed0", finished=True)
    make_run(sweep / "window-close" / "sac_stage2" / "seed1", finished=False)
    make_run(sweep / "drawer-open" / "sac_stage2" / "seed0", finished=True)
    make_run(sweep / "push" / "sac_stage2_randomgoal" / "seed0", finished=True,
             evaluated=True)
    # The latest launch into the shared sweep folder was another study's.
    (sweep / "multirun.yaml").write_text(yaml.safe_dump({"hydra": {
        "runtime": {"cwd": str(tmp_path / "machine")},
        "overrides": {"task": ["+study=another_study"]}}}))

    copied = collect_study(sweep, tmp_path / "results", ["window-close/*/*"])

    run = tmp_path / "results" / "window-close" / "sac_stage2" / "seed0"
    assert copied == [run]
    assert sorted(path.relative_to(run).as_posix() for path in run.rglob("*")) == [
        "config.json", "episodes.csv", "logs", "logs/seed0", "logs/seed0/scalars",
        "logs/seed0/scalars/loss.csv", "metrics.jsonl", "provenance.json", "summary.json"]
    assert sorted(path.name for path in (tmp_path / "results").iterdir()) == ["window-close"]

    copied = collect_study(sweep, tmp_path / "evaluated", ["push/*/*"])
    assert (copied[0] / "eval.csv").read_text() == "episode,env_steps\n10,5000\n"


def test_run_paths_are_relative_to_the_folders_given(tmp_path):
    root, other = tmp_path / "a" / "runs", tmp_path / "b"
    run = root / "push" / "sac_stage2" / "seed3"
    assert relative_run_path(run, [root]) == "push/sac_stage2/seed3"
    assert relative_run_path(run, [other, root]) == "runs/push/sac_stage2/seed3"
    assert relative_run_path(tmp_path / "c" / "t" / "m" / "seed0", [root]) == "t/m/seed0"


def test_no_committed_results_file_holds_a_machine_path():
    offending = []
    for path in sorted((REPOSITORY / "docs" / "results").rglob("*")):
        if path.suffix not in {".md", ".csv", ".json", ".jsonl", ".yaml", ".txt"}:
            continue
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if MACHINE_PATH.search(line):
                offending.append(f"{path.relative_to(REPOSITORY)}:{number}: {line[:120]}")
    assert not offending, "machine paths in committed results:\n" + "\n".join(offending)
