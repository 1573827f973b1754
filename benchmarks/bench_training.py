"""Training throughput: the updates against their compute bound, the whole loop, the replay.

Sections (``--sections``, default all but ``default_loop_rate``), each a module of
``benchmarks/training/`` named for what it runs, each row next to its reference measured in the
same run; a short name in brackets selects its section too:

sac_update (sac)          the SAC update alone: the recipe's against its bound, TorchRL's
                          ``SACLoss`` and plain PyTorch; compiled against eager
head_update (heads)       the reward-head update alone against its bound and the losses
                          scored term by term
training_step (step)      the recipe's step (head update, SAC batch and relabelling, SAC
                          update) against its bound; compiled against eager in ``--repeats``
                          fresh builds; compile's ceiling
default_loop (loop)       the default loop against its bound and ceiling, compiled against
                          eager in fresh processes, and ``--baseline-rev``'s loop
d_sequence (sequence)     d_sequence against D3: head updates, steps, ``--rounds`` loops
loop_grid (grid)          the loop by encoder, ``env.num_envs`` and compilation
plain_loop (reference)    the recipe without a VLM reward against a plain TorchRL SAC loop
replay                    replay sampling and memory against TorchRL's ``SliceSampler``
default_loop_rate (default)  the default loop's rate alone (what ``default_loop`` runs in each
                          fresh process)

``--threads`` sets torch's threads (default: all cores). ``--quick`` shortens everything;
``--smoke`` runs every section at tiny sizes, to check that it runs (its figures mean nothing).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
import training  # noqa: F401  (first: puts the measured tree on sys.path, before _common)
from _common import machine_description, report
from training.bounds import gemm_flops_per_second
from training.common import BUDGETS, Budget
from training.d_sequence import sequence_head_rows, sequence_rows
from training.default_loop import default_loop_rows, loop_rows
from training.head_update import heads_rows
from training.loop_grid import grid_rows
from training.plain_loop import reference_rows
from training.replay import replay_rows
from training.sac_update import sac_rows
from training.training_step import step_rows

import temporal_torchrl

Rows = Callable[[argparse.Namespace, Path, Budget, float], list[dict]]


@dataclass(frozen=True)
class Section:
    """A section: its short name (if any), whether it needs the machine's GEMM rate, and its
    rows from the command line's arguments, a temporary directory, the budget and that rate."""

    alias: str | None
    rows: Rows
    gemm_rate: bool = False


SECTIONS = {
    "sac_update": Section("sac", lambda args, tmp, budget, peak: sac_rows(
        tmp, budget, args.compile_mode)),
    "head_update": Section("heads", lambda args, tmp, budget, peak: heads_rows(
        tmp, budget, peak), gemm_rate=True),
    "training_step": Section("step", lambda args, tmp, budget, peak: step_rows(
        tmp, budget, args.compile_mode, args.repeats)),
    "default_loop": Section("loop", lambda args, tmp, budget, peak: loop_rows(
        tmp, budget, args.baseline_rev, peak, args.compile_mode), gemm_rate=True),
    "d_sequence": Section("sequence", lambda args, tmp, budget, peak: [
        *sequence_head_rows(tmp, budget), *sequence_rows(tmp, budget, args.rounds)]),
    "loop_grid": Section("grid", lambda args, tmp, budget, peak: grid_rows(
        tmp, budget, args.skip_liv, args.compile_mode)),
    "plain_loop": Section("reference", lambda args, tmp, budget, peak: reference_rows(
        tmp, budget)),
    "replay": Section(None, lambda args, tmp, budget, peak: replay_rows(budget)),
    "default_loop_rate": Section("default", lambda args, tmp, budget, peak: default_loop_rows(
        tmp, budget, args.compile_mode if args.default_compiled else None)),
}
#: What ``--sections`` runs when it is not given.
ALL = tuple(name for name in SECTIONS if name != "default_loop_rate")
ALIASES = {section.alias: name for name, section in SECTIONS.items() if section.alias}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="shorter timings")
    size.add_argument("--smoke", action="store_true",
                      help="tiny sizes: checks that each section runs (for the tests)")
    parser.add_argument("--sections", default=",".join(ALL),
                        help=f"comma-separated sections: {', '.join(SECTIONS)}, or their short "
                             f"names {', '.join(ALIASES)} (default: all but default_loop_rate)")
    parser.add_argument("--threads", type=int, default=os.cpu_count(),
                        help="torch threads (default: all cores)")
    parser.add_argument("--skip-liv", action="store_true", help="no LIV loop rows")
    parser.add_argument("--compile-mode", default="max-autotune",
                        help="torch.compile mode of the compiled rows (default: max-autotune, "
                             "the mode that pays off on a CPU)")
    parser.add_argument("--repeats", type=int, default=5,
                        help="fresh eager and compiled builds of the training_step section "
                             "(default 5)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="alternating loop runs of d_sequence and D3 in the d_sequence "
                             "section (default 3)")
    parser.add_argument("--default-compiled", action="store_true",
                        help="the default_loop_rate section's loop compiled (--compile-mode); "
                             "the default_loop section runs it so, alternating with eager")
    parser.add_argument("--baseline-rev", default=None,
                        help="git revision whose default loop the default_loop section "
                             "measures too (one whose recipe has the on_episode_end hook)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats {args.repeats}: expected an integer >= 1 (fresh builds of "
                     "the training_step section).")
    if args.rounds < 1:
        parser.error(f"--rounds {args.rounds}: expected an integer >= 1 (loop runs of each "
                     "reward in the d_sequence section).")
    requested = args.sections.split(",")
    if unknown := sorted(set(requested) - {*SECTIONS, *ALIASES}):
        parser.error(f"unknown sections {unknown}; choose from {', '.join(SECTIONS)} (or "
                     f"{', '.join(ALIASES)})")
    args.sections = [ALIASES.get(name, name) for name in requested]
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    budget = BUDGETS["smoke" if args.smoke else "quick" if args.quick else "full"]
    torch.set_num_threads(args.threads)
    print(f"machine: {machine_description()}; package: "
          f"{Path(temporal_torchrl.__file__).parent}", flush=True)
    sections = [name for name in SECTIONS if name in args.sections]
    peak = (gemm_flops_per_second(min_seconds=budget.seconds / 2)
            if any(SECTIONS[name].gemm_rate for name in sections) else float("nan"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in sections:
            rows += SECTIONS[name].rows(args, Path(tmp), budget, peak)
    report("Training updates, step, whole loop and replay buffer", rows, args.json)


if __name__ == "__main__":
    main()
