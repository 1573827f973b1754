"""Recount each run's RAS, the release's window, TTFS and TT50S from its episodes.csv alone.

An independent check of the report (``recipes/report.py``): the standard library only, no code
of the project's. RAS(e; 150) counts the successes of episodes e-149 .. e (thesis 5.1); the
thesis release's window is episodes e-154 .. e-5; TTFS and TT50S are the episodes of the first
and the 50th success ("> e" when not reached within the run).

    python docs/results/table_5_12/recount.py docs/results/table_5_12/runs
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from statistics import mean, stdev

WINDOW = 150


def recount(run: Path) -> dict:
    with (run / "episodes.csv").open() as file:
        successes = [int(row["success"]) for row in csv.DictReader(file)]
    config = json.loads((run / "config.json").read_text())
    budget = len(successes)
    wins = [episode for episode, success in enumerate(successes, start=1) if success]
    return {"task": config["env"]["task"], "configuration": run.parent.name,
            "seed": config["env"]["seed"], "episodes": budget,
            "ras": 100 * sum(successes[budget - WINDOW:]) / WINDOW,
            "release_window": 100 * sum(successes[budget - WINDOW - 5:budget - 5]) / WINDOW,
            "ttfs": wins[0] if wins else f"> {budget}",
            "tt50s": wins[49] if len(wins) >= 50 else f"> {budget}"}


def main(roots: list[str]) -> None:
    rows = [recount(config.parent) for root in roots
            for config in sorted(Path(root).rglob("config.json"))]
    cells: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        print(row)
        cells.setdefault((row["task"], row["configuration"]), []).append(row)
    for (task, configuration), runs in cells.items():
        values = [run["ras"] for run in runs]
        spread = f" ± {stdev(values):.1f}" if len(values) > 1 else ""
        print(f"{task} {configuration}: RAS {mean(values):.2f}{spread} over {len(values)} runs, "
              f"release window {mean(run['release_window'] for run in runs):.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
