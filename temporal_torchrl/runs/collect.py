"""A study's raw files, copied out of its sweep so that they can be committed.

A finished run's raw files are what the reports read: its config, summary, provenance, episode
rows, periodic
evaluations (``eval.csv``, where the run evaluated) and logged metrics (``metrics.jsonl`` and the
CSV logger's ``logs/``). Its checkpoints and replay episodes (megabytes a run, needed only to
resume it or to plot its reward curves) stay in the sweep. Hydra's ``multirun.yaml`` is not copied:
a sweep folder holds one, which each launch rewrites with its own overrides, while a study's runs
may come from several launches and share the folder with other studies' runs, so the file would
record whichever launch came last. A run's ``config.json`` is the whole resolved config it ran; the
study's README names its launches.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

from temporal_torchrl.runs.layout import (
    CONFIG_FILE,
    EPISODES_FILE,
    EVALUATION_FILE,
    LOGS_DIR,
    METRICS_FILE,
    PROVENANCE_FILE,
    SUMMARY_FILE,
)

#: What a committed run holds: files, then folders.
RAW_FILES = (CONFIG_FILE, SUMMARY_FILE, EPISODES_FILE, EVALUATION_FILE, METRICS_FILE,
             PROVENANCE_FILE)
RAW_FOLDERS = (LOGS_DIR,)


def finished_runs(sweep: Path, patterns: Sequence[str] = ("**",)) -> list[Path]:
    """The run directories under ``sweep`` that hold a summary (the recipe writes it last) and
    match one of the glob ``patterns`` (relative to ``sweep``, e.g. ``window-close/*/*``)."""
    found = {summary.parent for pattern in patterns
             for summary in Path(sweep).glob(f"{pattern.rstrip('/')}/{SUMMARY_FILE}")}
    return sorted(found)


def copy_raw_files(run: Path, destination: Path) -> list[Path]:
    """Copy ``run``'s raw files into ``destination`` (replacing what is there); returns them."""
    destination.mkdir(parents=True, exist_ok=True)
    copied = []
    for name in RAW_FILES:
        if (run / name).is_file():
            shutil.copy2(run / name, destination / name)
            copied.append(destination / name)
    for name in RAW_FOLDERS:
        if (run / name).is_dir():
            shutil.rmtree(destination / name, ignore_errors=True)
            shutil.copytree(run / name, destination / name)
            copied.append(destination / name)
    return copied


def collect_study(sweep: Path, destination: Path,
                  patterns: Sequence[str] = ("**",)) -> list[Path]:
    """Copy every finished run of ``sweep`` that matches ``patterns`` into ``destination`` under
    the same relative paths; returns the runs copied (in ``destination``)."""
    sweep, destination = Path(sweep), Path(destination)
    copied = []
    for run in finished_runs(sweep, patterns):
        target = destination / run.relative_to(sweep)
        copy_raw_files(run, target)
        copied.append(target)
    return copied
