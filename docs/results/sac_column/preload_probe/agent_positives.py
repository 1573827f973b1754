"""Turn a finished SAC run's own successful episodes into a positives source for
``train.positives_from``: the release's kind of preload (agent-made, whole episodes, in the order
they happened) without a FuRL stage-1 run.

The thesis release preloads the first 50 successful episodes of a FuRL stage-1 run; the recipe by
default preloads scripted-expert episodes. A stage-2 SAC run of the same task and seed stores
every inserted episode in ``replay/`` (the 50 preloaded ones first, then training episode ``e``
at index ``49 + e``) and each episode's success in ``episodes.csv``. This script copies the first
``--count`` successful training episodes into ``<out>/positives/`` and the run's ``config.json``
beside them, which is what ``train.positives_from=<out>`` reads and checks (task and layout).

    python docs/results/sac_column/preload_probe/agent_positives.py \\
        sweeps/cpu_budget/drawer-open/sac_stage2/seed2 sweeps/preload_probe/positives/seed2
"""

from __future__ import annotations

import argparse
import csv
import shutil
from pathlib import Path

from temporal_torchrl.runs import RunDirectory


def successful_episodes(run: Path) -> list[int]:
    """The 1-based numbers of the run's successful training episodes, in order."""
    with (run / "episodes.csv").open() as file:
        return [int(row["episode"]) for row in csv.DictReader(file) if int(row["success"])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="a finished stage-2 run with its replay/")
    parser.add_argument("out", type=Path, help="the positives source to write")
    parser.add_argument("--count", type=int, default=50)
    args = parser.parse_args()

    source = RunDirectory(args.run)
    preloaded = source.config()["train"]["preload_positives"]
    episodes = successful_episodes(args.run)[:args.count]
    if len(episodes) < args.count:
        raise SystemExit(f"{args.run} has {len(episodes)} successful episodes, fewer than "
                         f"--count={args.count}.")
    if args.out.exists():
        raise SystemExit(f"{args.out} exists; remove it or pick another folder.")
    out = RunDirectory(args.out)
    args.out.mkdir(parents=True)
    shutil.copy(args.run / "config.json", args.out / "config.json")
    for episode in episodes:
        out.save_positive_episode(episode, source.replay.load(preloaded + episode - 1))
    print(f"{args.out}: training episodes {episodes[0]}..{episodes[-1]} of {args.run} "
          f"({len(episodes)} successes)")


if __name__ == "__main__":
    main()
