"""Recount each run's RAS, the release's window, TTFS and TT50S from its episodes.csv alone.

An independent check of the report (``recipes/report.py``): the standard library only, no code
of the project's. RAS(e; 150) counts the successes of episodes e-149 .. e at the task's budget e
(thesis Table 5.1, written out below); the thesis release's window is episodes e-154 .. e-5;
TTFS and TT50S are the episodes of the first and the 50th success ("> n" when not reached
within the run's n episodes). A run short of its budget has no RAS; a run beyond it is scored
at the budget. A run found under two roots (two studies' folders holding the same run: same
task, configuration and seed) counts once when its episodes.csv is the same, and stops the
recount when it is not.

    python docs/results/table_5_12/recount.py docs/results/sac_column/runs \
        docs/results/window_close_cpu_study/runs docs/results/table_5_12/runs --seeds 0 1 2 3
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
from pathlib import Path
from statistics import mean, stdev

WINDOW = 150
#: Thesis Table 5.1: the episode at which each task's RAS is taken.
BUDGETS = {"window-close": 200, "window-open": 200, "drawer-open": 300, "door-open": 400,
           "button-press-topdown": 400, "push": 1000}


def recount(run: Path) -> dict:
    text = (run / "episodes.csv").read_text()
    successes = [int(row["success"]) for row in csv.DictReader(text.splitlines())]
    config = json.loads((run / "config.json").read_text())
    task = config["env"]["task"]
    budget = BUDGETS[task]
    wins = [episode for episode, success in enumerate(successes, start=1) if success]
    complete = len(successes) >= budget
    return {"task": task, "configuration": run.parent.name, "seed": config["env"]["seed"],
            "episodes": len(successes), "budget": budget,
            "ras": 100 * sum(successes[budget - WINDOW:budget]) / WINDOW if complete else None,
            "release_window": (100 * sum(successes[budget - WINDOW - 5:budget - 5]) / WINDOW
                               if complete else None),
            "ttfs": wins[0] if wins else f"> {len(successes)}",
            "tt50s": wins[49] if len(wins) >= 50 else f"> {len(successes)}",
            "digest": hashlib.sha256(text.encode()).hexdigest()}


def unique_runs(roots: list[str]) -> list[dict]:
    """Every run under ``roots``, each (task, configuration, seed) once."""
    runs: dict[tuple, dict] = {}
    for root in roots:
        for config in sorted(Path(root).rglob("config.json")):
            row = recount(config.parent)
            key = (row["task"], row["configuration"], row["seed"])
            if key in runs and runs[key]["digest"] != row["digest"]:
                raise SystemExit(f"{key}: two runs with different episodes.csv "
                                 f"({runs[key]['path']} and {config.parent}).")
            runs.setdefault(key, {**row, "path": config.parent})
    return list(runs.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+")
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="count only these seeds (a plan's); default every seed")
    args = parser.parse_args()
    rows = [row for row in unique_runs(args.roots)
            if args.seeds is None or row["seed"] in args.seeds]
    cells: dict[tuple[str, str], list[dict]] = {}
    for row in sorted(rows, key=lambda row: (row["task"], row["configuration"], row["seed"])):
        print({key: value for key, value in row.items() if key not in ("digest", "path")})
        cells.setdefault((row["task"], row["configuration"]), []).append(row)
    for (task, configuration), runs in cells.items():
        scored = [run for run in runs if run["ras"] is not None]
        short = len(runs) - len(scored)
        note = f"; {short} short of the budget {runs[0]['budget']}" if short else ""
        if not scored:
            print(f"{task} {configuration}: no RAS yet{note}")
            continue
        values = [run["ras"] for run in scored]
        spread = f" ± {stdev(values):.1f}" if len(values) > 1 else ""
        print(f"{task} {configuration}: RAS {mean(values):.2f}{spread} over {len(values)} runs "
              f"at episode {runs[0]['budget']}, release window "
              f"{mean(run['release_window'] for run in scored):.2f}{note}")


if __name__ == "__main__":
    main()
