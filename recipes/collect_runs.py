"""Copy a sweep's finished runs into a study's results folder, ready to commit.

    python recipes/collect_runs.py sweeps/cpu_budget docs/results/sac_column/runs \
        --runs '*/sac_stage2/*'

Each finished run (it has a ``summary.json``) is copied with its config, summary, episode rows
and logged metrics, under the same relative path; checkpoints and replay episodes stay in the
sweep, as does Hydra's ``multirun.yaml``, which records only the sweep's latest launch
(:mod:`temporal_torchrl.runs.collect`). Then: ``python recipes/report.py <folder> --out ...``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from temporal_torchrl.runs.collect import collect_study


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sweep", type=Path, help="the sweep directory (hydra.sweep.dir)")
    parser.add_argument("destination", type=Path, help="the study's runs folder")
    parser.add_argument("--runs", nargs="+", default=["**"],
                        help="globs of run directories relative to the sweep "
                             "(default: all of them), e.g. 'window-close/*/*'")
    args = parser.parse_args(argv)
    if not args.sweep.is_dir():
        parser.error(f"{args.sweep} is not a directory: pass the sweep's hydra.sweep.dir.")
    copied = collect_study(args.sweep, args.destination, args.runs)
    if not copied:
        parser.error(f"no finished run in {args.sweep} matches {' '.join(args.runs)} (a "
                     "finished run has a summary.json).")
    for run in copied:
        print(run)
    print(f"copied {len(copied)} finished runs into {args.destination}")


if __name__ == "__main__":
    main()
