"""Section ``d_sequence`` (``sequence``): d_sequence (K = 8) against D3.

The reward-head update (FuRL beside the directional loss, D = 1024) and the training step in
stage 1 and 2, the two rewards alternating in one process; and the whole loop (state encoder,
D = 1024, 1 env, eager) in ``--rounds`` alternating runs of each.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable
from pathlib import Path

from training.bounds import alternating_seconds
from training.common import Budget, steady_steps_per_second, training_setup


def sequence_head_rows(tmp: Path, budget: Budget) -> list[dict]:
    """The reward-head update and the training step (head update, SAC batch and relabelling,
    SAC update) with d_sequence (K = 8) against D3, FuRL beside each, D = 1024, stage 1 and 2:
    ``budget.rounds`` alternating timings of the two in one process, the medians."""
    rows = []
    for stage in (1, 2):
        setups = {variant: training_setup(tmp, budget, 1024, f"reward.directional={variant}",
                                          stage=stage) for variant in ("d3", "d_sequence")}

        def step(setup: dict) -> Callable[[], None]:
            def run() -> None:
                setup["trainer"].update()
                setup["update_sac"](setup["buffer"].sample())
            return run

        for part, make in (("reward-head update", lambda setup: setup["trainer"].update),
                           ("training step", step)):
            times = alternating_seconds({variant: make(setup) for variant, setup in setups.items()},
                                        budget.rounds, budget.seconds / 4,
                                        min(3, budget.warmup_calls))
            d3, sequence = (1e3 * statistics.median(times[variant]) for variant in setups)
            print(f"{part}, stage {stage}: d_sequence {sequence:.1f} ms, D3 {d3:.1f} ms",
                  flush=True)
            rows.append({"measure": f"{part}, FuRL + d_sequence K=8, stage {stage}, D=1024, "
                                    f"eager, median of {len(times['d3'])} alternating (ms)",
                         "project": sequence, "reference": d3,
                         "reference is": "FuRL + D3, the same batch size and buffer",
                         "ratio": sequence / d3})
    return rows


def sequence_rows(tmp: Path, budget: Budget, rounds: int = 3) -> list[dict]:
    """d_sequence (K = 8) against D3 in the same loop: state encoder D = 1024, 1 env, eager;
    ``rounds`` runs of each, alternating, and the medians."""
    common = ["encoder.name=state", "+encoder.options.dim=1024"]
    d3, sequence = [], []
    for _ in range(rounds):
        d3.append(steady_steps_per_second([*common, "reward.directional=d3"], 1,
                                          budget.episode_length, tmp, budget))
        sequence.append(steady_steps_per_second([*common, "reward.directional=d_sequence"], 1,
                                                budget.episode_length, tmp, budget))
        print(f"d_sequence: {sequence[-1]:.1f}, D3: {d3[-1]:.1f} env steps/s", flush=True)
    ratios = sorted(a / b for a, b in zip(d3, sequence, strict=True))
    return [{"measure": f"whole loop, d_sequence K=8, state encoder D=1024, 1 env, eager, median "
                        f"of {rounds} alternating (env steps/s; ratio: D3's rate over it, the "
                        f"cost per env step; per round {' / '.join(f'{r:.2f}' for r in ratios)})",
             "project": statistics.median(sequence), "reference": statistics.median(d3),
             "reference is": "D3, the same loop",
             "ratio": statistics.median(d3) / statistics.median(sequence)}]
