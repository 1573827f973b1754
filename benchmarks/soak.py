"""Soak: a long render-free run of the recipe, watched from outside for leaks.

Runs ``recipes/sac_temporal.py`` (the state encoder, short episodes, small networks, a checkpoint
and a replay episode written every episode, the CSV logger) for ``--episodes`` episodes in a
subprocess and samples, every ``--interval`` seconds, its resident memory (``VmRSS``), the
episodes finished (``episodes.csv``) and the run directory's size. Reports a row every tenth of
the run and the least-squares slopes after the warm-up (the first ``--warmup`` episodes: the
replay storage is allocated at the first insert, the optimizers' state at the first update):
resident memory per 100 episodes (flat is the target), seconds per episode per 100 episodes,
and the run directory's bytes per episode (it grows by design: one replay episode, one
episodes.csv row and a few log lines per episode).

    python benchmarks/soak.py                       # 1,000 episodes of 20 steps, CSV logger
    python benchmarks/soak.py --logger none         # the same without a logger
    python benchmarks/soak.py --episodes 200 --json soak.json
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from _common import machine_description, report

RECIPE = Path(__file__).resolve().parents[1] / "recipes" / "sac_temporal.py"


def resident_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def episodes_done(run_dir: Path) -> int:
    try:
        with (run_dir / "episodes.csv").open() as file:
            return max(0, sum(1 for _ in file) - 1)
    except OSError:
        return 0


def directory_bytes(path: Path) -> int:
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            try:
                total += (Path(root) / name).stat().st_size
            except OSError:  # a temporary file renamed away meanwhile
                pass
    return total


def slope(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.polyfit(x, y, 1)[0])


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=20, help="env steps per episode")
    parser.add_argument("--warmup", type=int, default=50, help="episodes left out of the slopes")
    parser.add_argument("--interval", type=float, default=0.5, help="seconds between samples")
    parser.add_argument("--threads", type=int, default=1, help="the run's torch threads")
    parser.add_argument("--logger", default="csv", choices=("csv", "none"),
                        help="logger.backend (TorchRL's CSV logger keeps every value in memory)")
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = parser.parse_args(argv)

    run_dir = Path(tempfile.mkdtemp(prefix="soak_")) / "run"
    command = [sys.executable, str(RECIPE), "encoder.name=state", "+encoder.options.dim=32",
               f"env.max_episode_steps={args.steps}", f"train.episodes={args.episodes}",
               "train.random_steps=100", "sac.batch_size=64", "sac.hidden_sizes=[64,64]",
               "reward.batch_size=64", "reward.gap=3", f"logger.backend={args.logger}",
               "logger.log_every=100", "train.progress=false", f"train.threads={args.threads}",
               f"output_dir={run_dir}"]
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               text=True)
    samples = []  # (seconds, episodes, resident MB, directory bytes)
    while process.poll() is None:
        memory = resident_mb(process.pid)
        if memory is not None:
            samples.append((time.perf_counter() - started, episodes_done(run_dir), memory,
                            directory_bytes(run_dir)))
        time.sleep(args.interval)
    if process.returncode != 0:
        raise SystemExit(f"the run failed ({process.returncode}):\n{process.stderr.read()[-3000:]}")
    seconds, episodes, memory, size = (np.array(column, dtype=float)
                                       for column in zip(*samples, strict=True))

    # Training samples only: the last ones are taken while the process writes its summary and
    # exits, having freed the collector.
    training = episodes < args.episodes
    seconds, episodes, memory, size = (column[training] for column in
                                       (seconds, episodes, memory, size))
    rows = []
    previous = None
    for mark in np.linspace(0, args.episodes, 11).astype(int)[1:]:
        index = int(np.argmax(episodes >= mark)) if (episodes >= mark).any() else len(episodes) - 1
        if index == previous:  # the last rows, past the last training sample
            continue
        pace = ("-" if previous is None else round(
            (seconds[index] - seconds[previous]) / max(episodes[index] - episodes[previous], 1), 3))
        rows.append({"episode": int(episodes[index]), "elapsed s": round(seconds[index], 1),
                     "resident MB": round(memory[index], 1), "s/episode since last row": pace,
                     "run dir MB": round(size[index] / 2**20, 2)})
        previous = index
    steady = episodes >= args.warmup
    second_half = episodes >= args.episodes // 2
    # Per-episode times from the moments episodes.csv grew, after the warm-up.
    grew = np.flatnonzero(np.diff(episodes) > 0) + 1
    grew = grew[episodes[grew] >= args.warmup]
    pace = np.diff(seconds[grew]) / np.diff(episodes[grew])
    summary = {
        "episodes": args.episodes, "steps per episode": args.steps,
        "wall s": round(float(seconds[-1]), 1),
        "resident MB after warm-up": round(float(memory[steady][0]), 1),
        "resident MB, last episode": round(float(memory[-1]), 1),
        "resident MB per 100 episodes (slope)": round(100 * slope(episodes[steady],
                                                                   memory[steady]), 3),
        "the same, second half": round(100 * slope(episodes[second_half], memory[second_half]),
                                       3),
        "s/episode, mean after warm-up": round(float(pace.mean()), 4),
        "s/episode per 100 episodes (slope)": round(100 * slope(episodes[grew][1:], pace), 5),
        "run dir KB per episode (slope)": round(slope(episodes[steady], size[steady]) / 1024, 2),
        "run dir MB, end": round(directory_bytes(run_dir) / 2**20, 2),
    }
    report(f"Soak: {args.episodes} episodes of {args.steps} steps, state encoder, "
           f"{args.threads} torch thread(s), logger {args.logger} (run in {run_dir})", rows)
    report("Soak: slopes after the first "
           f"{args.warmup} episodes ({len(samples)} samples, every {args.interval} s)",
           [summary], args.json)
    print(f"\nmachine: {machine_description()}; date: {time.strftime('%Y-%m-%d')}")


if __name__ == "__main__":
    main()
