"""Section ``training_step`` (``step``): the training step as the recipe runs it.

One reward-head update, one SAC batch sampled and relabelled, one SAC update; stage 2,
D = 1024. Eager against the compute bound and its matmuls alone; compiled (``torch.compile``)
against eager in ``repeats`` fresh builds (min, median, max), with the compile time of the
first; and compile's ceiling: the eager step with the parts it compiles (the head losses'
forward and backward, the relabelling's reward, the SAC update) cut to their matmuls alone.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch

from training.bounds import (
    bound_row_by_round,
    counted_flops,
    gemm_flops_per_second,
    matmul_row,
    matmuls_alone,
    spread,
)
from training.common import Budget, training_setup


def training_step(compiled: bool, tmp: Path, budget: Budget,
                  mode: str | None = None) -> Callable[[], None]:
    """The recipe's step (head update, SAC batch + relabel, SAC update) on a stage-2 buffer,
    compiled in ``mode`` when ``compiled``."""
    setup = training_setup(tmp, budget, 1024, f"compile.enabled={str(compiled).lower()}",
                           f"compile.mode={mode or 'null'}")
    trainer, buffer, update_sac = setup["trainer"], setup["buffer"], setup["update_sac"]

    def step() -> None:
        trainer.update()
        update_sac(buffer.sample())

    return step


def compiled_regions(tmp: Path, budget: Budget) -> list[Callable[[], object]]:
    """The parts of the step that ``compile.enabled`` compiles, eager, each on a fixed batch:
    the reward-head losses' forward and backward, the relabelling's reward call and the SAC
    update."""
    setup = training_setup(tmp, budget, 1024)
    trainer, buffer = setup["trainer"], setup["buffer"]
    batch = trainer.replay.sample(trainer.batch_size)
    relabel = buffer.transform[-1]
    transitions = buffer.sample()

    def losses() -> None:
        torch.stack([loss(batch)[loss.loss_key] for loss in trainer.losses]).sum().backward()

    return [losses, lambda: relabel(transitions), lambda: setup["update_sac"](transitions)]


def step_rows(tmp: Path, budget: Budget, mode: str | None, repeats: int) -> list[dict]:
    """Eager and compiled against the bound, each build against the GEMM rate measured just
    before it; compiled against eager in ``repeats`` fresh builds (dynamo reset before each, so
    each compiles anew; inductor's on-disk cache serves the later ones, and the first too when
    an earlier run on the machine filled it)."""
    step = training_step(False, tmp, budget)
    flops = counted_flops(step)
    matmul_seconds = budget.seconds_per_call(matmuls_alone(step))
    # What compile could give if it removed everything but the matmuls of what it compiles.
    regions = compiled_regions(tmp, budget)
    eager_times, compiled_times, compile_times, peaks = [], [], [], []
    region_times, region_matmul_times = [], []
    for _ in range(repeats):
        peaks.append(gemm_flops_per_second(min_seconds=budget.seconds / 4))
        torch._dynamo.reset()
        eager = training_step(False, tmp, budget)
        eager_times.append(budget.seconds_per_call(eager))
        # The compiled parts timed in the same round as the step they are part of: timed
        # minutes apart, a change of the machine's load put them above the whole step. A round
        # whose parts still time above its step counts the step as all compiled parts.
        region_times.append(sum(budget.seconds_per_call(fn) for fn in regions))
        region_matmul_times.append(
            sum(budget.seconds_per_call(matmuls_alone(fn)) for fn in regions))
        compiled = training_step(True, tmp, budget, mode)
        start = time.perf_counter()
        for _ in range(3):  # compilation, and the recompile at the first stage-2 graph
            compiled()
        compile_times.append(time.perf_counter() - start)
        compiled_times.append(budget.seconds_per_call(compiled))
        print(f"step: eager {1000 * eager_times[-1]:.1f} ms, compiled "
              f"{1000 * compiled_times[-1]:.1f} ms (compiled in {compile_times[-1]:.0f} s)",
              flush=True)
    speedups = sorted(e / c for e, c in zip(eager_times, compiled_times, strict=True))
    eager_seconds = statistics.median(eager_times)
    region_seconds = statistics.median(region_times)
    region_matmul_seconds = statistics.median(region_matmul_times)
    ceiling = statistics.median(
        eager / max(eager - region + matmul, matmul)
        for eager, region, matmul in zip(eager_times, region_times, region_matmul_times,
                                         strict=True))
    return [
        bound_row_by_round(f"training step, eager, median of {repeats} builds (ms)",
                           eager_times, flops, peaks),
        matmul_row(f"training step, eager, median of {repeats} (ms)", eager_seconds,
                   matmul_seconds),
        bound_row_by_round(f"training step, compiled ({mode}), median of {repeats} builds (ms)",
                           compiled_times, flops, peaks),
        {"measure": f"training step, compiled vs eager (speed-up, {repeats} builds: "
                    f"{spread(speedups)}; compile {compile_times[0]:.0f} s in the first build, "
                    f"{statistics.median(compile_times[1:] or compile_times):.0f} s in the "
                    "others)",
         "project": speedups[0], "reference": 1.0, "reference is": "eager (min shown)",
         "ratio": speedups[0]},
        {"measure": f"training step, compile's ceiling: eager with the compiled parts "
                    f"({1000 * region_seconds:.1f} ms eager) cut to their matmuls "
                    f"({1000 * region_matmul_seconds:.1f} ms) (speed-up)",
         "project": ceiling, "reference": 1.0, "reference is": "eager", "ratio": ceiling},
    ]
