"""Section ``default_loop`` (``loop``): the whole default loop against its bound.

The default run's loop (the shipped encoder at 64 px, FuRL + D3, stage 1 with relay, 1 env,
eager), env steps/s in the steady state (the 3rd and 4th episodes, timed at their ends: the 1st
has no updates), against its bound (its env side, measured without updates, plus its updates'
FLOPs at the GEMM rate), its ceiling (the env side plus its updates' matmuls alone), compiled
(``--compile-mode``) against eager in alternating fresh processes, and, with
``--baseline-rev REV``, against that git revision's loop, run from a worktree in a fresh
process too. Each fresh process is ``bench_training.py --sections default_loop_rate`` (one rate,
:func:`default_loop_rows`) on the tree that ``TEMPORAL_TORCHRL_TREE`` names.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

import torch

from training import TREE
from training.bounds import counted_flops, matmuls_alone, spread
from training.common import RUN_IDS, Budget, steady_steps_per_second, training_setup

#: The default run's loop: the shipped encoder at 64 px, FuRL + D3, stage 1 (relay on), 1 env.
DEFAULT_LOOP = ("encoder.name=metaworld_small", "env.image_size=64")
BENCH_TRAINING = Path(__file__).resolve().parents[1] / "bench_training.py"


def default_loop_rows(tmp: Path, budget: Budget, compile_mode: str | None = None) -> list[dict]:
    """The default loop's rate in this process, eager, or compiled with ``compile_mode`` when it
    is given: one row, without a reference."""
    compiled = ["compile.enabled=true", f"compile.mode={compile_mode}"] if compile_mode else []
    rate = steady_steps_per_second([*DEFAULT_LOOP, *compiled], 1, budget.episode_length, tmp,
                                   budget)
    how = f"compiled ({compile_mode})" if compile_mode else "eager"
    return [{"measure": f"whole default loop, shipped encoder 64 px, 1 env, {how} (env steps/s)",
             "project": rate, "reference": float("nan"), "reference is": "-",
             "ratio": float("nan")}]


def fresh_default_loop(tmp: Path, budget: Budget, tree: Path,
                       compile_mode: str | None = None) -> float:
    """The default loop's rate (compiled with ``compile_mode`` when given), measured by
    ``bench_training.py`` in a fresh process on ``tree``'s recipe and package."""
    out = tmp / f"default_{next(RUN_IDS)}.json"
    compiled = ["--compile-mode", compile_mode, "--default-compiled"] if compile_mode else []
    size = [] if budget.name == "full" else [f"--{budget.name}"]
    command = [sys.executable, str(BENCH_TRAINING), "--sections", "default_loop_rate",
               "--json", str(out), "--threads", str(torch.get_num_threads()), *size, *compiled]
    done = subprocess.run(command, env={**os.environ, "TEMPORAL_TORCHRL_TREE": str(tree)})
    if done.returncode != 0:
        raise SystemExit(f"the default loop on {tree} failed (exit status {done.returncode}; "
                         "its error is above).")
    return json.loads(out.read_text())["rows"][0]["project"]


def loop_rows(tmp: Path, budget: Budget, revision: str | None, peak: float,
              compile_mode: str | None) -> list[dict]:
    """The default loop here, eager and compiled (``compile_mode``), and (``revision``) at that
    git revision, each in a fresh process (the revision's from a worktree; with
    ``budget.fresh_processes`` off, this tree's in this one), alternating,
    ``budget.loop_rounds`` times each; and the most that faster updates could give it: its env
    side (the same loop without updates) plus its updates' FLOPs at the GEMM rate ``peak``, or
    their matmuls alone."""
    def rate(tree: Path, mode: str | None = None) -> float:
        if budget.fresh_processes or tree != TREE:
            return fresh_default_loop(tmp, budget, tree, mode)
        return default_loop_rows(tmp, budget, mode)[0]["project"]

    length = budget.episode_length
    ours, compiled, theirs = [], [], []
    worktree = tmp / "baseline"
    if revision is not None:
        added = subprocess.run(["git", "-C", str(TREE), "worktree", "add", "--detach",
                                str(worktree), revision], capture_output=True, text=True)
        if added.returncode != 0:
            raise SystemExit(f"--baseline-rev {revision!r}: git could not check it out "
                             f"({added.stderr.strip()}); pass a commit, tag or branch of "
                             f"{TREE}, e.g. --baseline-rev HEAD~1.")
    try:
        for _ in range(budget.loop_rounds):
            ours.append(rate(TREE))
            compiled.append(rate(TREE, compile_mode))
            print(f"default loop: {ours[-1]:.1f} eager, {compiled[-1]:.1f} compiled", flush=True)
            if revision is None:
                continue
            theirs.append(rate(worktree))
            print(f"default loop: {ours[-1]:.1f} here, {theirs[-1]:.1f} at {revision}",
                  flush=True)
    finally:
        if revision is not None:
            subprocess.run(["git", "-C", str(TREE), "worktree", "remove", "--force",
                            str(worktree)], check=False, capture_output=True)
    here = statistics.median(ours)
    today, today_is = ((statistics.median(theirs), f"the same loop at {revision}")
                       if revision is not None else (here, "the loop here"))
    env_rate = steady_steps_per_second(
        [*DEFAULT_LOOP, "train.utd_ratio=0", "train.reward_updates_per_step=0"], 1, length, tmp,
        budget)
    # Per env step in stage 1 with relay: one head update, one SAC batch, two SAC updates.
    setup = training_setup(tmp, budget, 256, stage=1)
    batch = setup["buffer"].sample()
    updates = (setup["trainer"].update, setup["buffer"].sample,
               lambda: setup["update_sac"](batch))
    weights = (1, 1, 2)
    flops = sum(n * counted_flops(fn) for n, fn in zip(weights, updates, strict=True))
    bound = 1.0 / (1.0 / env_rate + flops / peak)
    matmul_seconds = sum(n * budget.seconds_per_call(matmuls_alone(fn), 0.5)
                         for n, fn in zip(weights, updates, strict=True))
    ceiling = 1.0 / (1.0 / env_rate + matmul_seconds)
    print(f"default loop: env side {env_rate:.1f} steps/s, updates {flops / 1e9:.2f} GFLOP a "
          "step", flush=True)
    speedups = [c / e for c, e in zip(compiled, ours, strict=True)]
    rounds = len(ours)
    return [{"measure": f"whole default loop, shipped encoder 64 px, 1 env, eager, median of "
                        f"{rounds} (env steps/s)", "project": here, "reference": today,
             "reference is": today_is, "ratio": here / today},
            {"measure": f"whole default loop, compiled ({compile_mode}), median of {rounds} "
                        "alternating with eager (env steps/s; steady state, compile time not "
                        "in it)", "project": statistics.median(compiled), "reference": here,
             "reference is": f"the loop here, eager (speed-up by round: {spread(speedups)})",
             "ratio": statistics.median(compiled) / here},
            {"measure": f"whole default loop, bound: its env side ({env_rate:.1f} steps/s "
                        f"without updates) + {flops / 1e9:.2f} GFLOP of updates a step at "
                        f"{peak / 1e9:.0f} GFLOP/s (env steps/s)", "project": bound,
             "reference": today, "reference is": today_is, "ratio": bound / today},
            {"measure": f"whole default loop, ceiling: its env side + its updates' matmuls "
                        f"alone ({1000 * matmul_seconds:.1f} ms a step) (env steps/s)",
             "project": ceiling, "reference": today, "reference is": today_is,
             "ratio": ceiling / today}]
