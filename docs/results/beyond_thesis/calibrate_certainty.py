"""Calibration of d_certainty's certainty target (bandwidth beta, pseudo-count c).

On the offline reward-quality benchmark's training episodes (the same cached datasets, split and
replay buffer as ``recipes/evaluate_rewards.py``), draws finetuning batches (256 positive and 256
negative states, as the training recipe) and averages, per (beta, c), the targets
:class:`~temporal_torchrl.objectives.CertaintyLoss` computes for the directions it scores:

- observed positive / negative: s_t - s_(t-k) of the batch's positive / negative states (each
  leaving itself out of the references);
- opposite: s_(t-k) - s_t at a positive state;
- towards the goal: s_g - s_t at a negative state;
- unseen: a random direction at a positive state (no episode took it: the target should be ~0).

    OMP_NUM_THREADS=1 python docs/results/beyond_thesis/calibrate_certainty.py \
        env.task=[drawer-open,door-open,window-open,window-close,push,button-press-topdown]

Writes ``docs/results/beyond_thesis/certainty_calibration.md``. Overrides are those of
``recipes/evaluate_rewards.py`` (its config is the one composed).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir

from temporal_torchrl.configs.rules import (
    config_tasks,
    resolve_device,
    validate_reward_quality_config,
)
from temporal_torchrl.machine import machine_description
from temporal_torchrl.reward_quality import (
    make_finetuning_buffer,
    prepare_task,
    task_config,
)
from temporal_torchrl.rewards import direction_certainty, reference_scales
from temporal_torchrl.training import factories

#: The recipes' config folder, whose ``evaluate_rewards.yaml`` the study composes.
RECIPES = Path(__file__).resolve().parents[3] / "recipes"

BANDWIDTHS = (0.05, 0.1, 0.2, 0.3)
PRIORS = (0.5, 1.0, 2.0)
BATCHES = 20
KINDS = ("observed positive", "observed negative", "opposite", "towards goal", "unseen")


def task_targets(cfg, encoder) -> dict[tuple[float, float], dict[str, float]]:
    """Mean target per query kind, per (beta, c), over BATCHES batches of one task."""
    data = prepare_task(cfg, encoder)
    train, goal = data.train, data.goal_image
    buffer = make_finetuning_buffer(train.episodes, k=cfg.reward.k,
                                    label_window=cfg.reward.label_window)
    generator = torch.Generator().manual_seed(cfg.env.seed)
    sums = {(beta, prior): dict.fromkeys(KINDS, 0.0) for beta in BANDWIDTHS for prior in PRIORS}
    for _ in range(BATCHES):
        batch = buffer.finetuning.sample(cfg.reward.batch_size)
        positive, negative = batch["positive"], batch["negative"]
        positions = torch.cat([positive["embedding"], negative["embedding"]])
        directions = positions - torch.cat([positive["previous_embedding"],
                                            negative["previous_embedding"]])
        count = positive.shape[0]
        labels = torch.cat([torch.ones(count), -torch.ones(negative.shape[0])])
        scales = reference_scales(positions, directions)
        leave_one_out = torch.eye(labels.numel(), dtype=torch.bool)
        random_directions = torch.randn(count, positions.shape[-1], generator=generator)
        queries = {"opposite": (positive["embedding"], -directions[:count]),
                   "towards goal": (negative["embedding"], goal - negative["embedding"]),
                   "unseen": (positive["embedding"], random_directions)}
        for key, totals in sums.items():
            beta, prior = key
            common = {"bandwidth": beta, "prior": prior, "scales": scales}
            observed = direction_certainty(positions, directions, positions, directions, labels,
                                           exclude=leave_one_out, **common)
            totals["observed positive"] += float(observed[:count].mean()) / BATCHES
            totals["observed negative"] += float(observed[count:].mean()) / BATCHES
            for kind, (query_positions, query_directions) in queries.items():
                totals[kind] += float(direction_certainty(
                    query_positions, query_directions, positions, directions, labels,
                    **common).mean()) / BATCHES
    return sums


def main(overrides: list[str]) -> None:
    torch.set_num_threads(1)
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("evaluate_rewards", overrides=overrides)
    cfg = validate_reward_quality_config(cfg)
    encoder = factories.make_encoder(cfg, resolve_device(cfg.encoder.device))
    start = time.perf_counter()
    tasks = config_tasks(cfg)
    per_task = {task: task_targets(task_config(cfg, task), encoder)
                for task in tasks}
    lines = [
        "# d_certainty: calibration of the certainty target", "",
        f"Mean certainty target t per query kind, over {BATCHES} finetuning batches "
        f"({cfg.reward.batch_size} positive and {cfg.reward.batch_size} negative states) of the "
        f"reward-quality benchmark's training episodes, averaged over {', '.join(tasks)}; "
        f"encoder {encoder.name} ({encoder.dim}-d), k = {cfg.reward.k}. The observed "
        "directions leave themselves out; 'unseen' is a random direction at a positive state.",
        "", f"- command: `python docs/results/beyond_thesis/calibrate_certainty.py "
        f"{' '.join(overrides)}`",
        f"- machine: {machine_description()}; wall time "
        f"{time.perf_counter() - start:.0f} s", "",
        "| beta | c | " + " | ".join(KINDS) + " |", "|---|---|" + "---|" * len(KINDS)]
    for beta in BANDWIDTHS:
        for prior in PRIORS:
            means = [sum(per_task[task][beta, prior][kind] for task in tasks) / len(tasks)
                     for kind in KINDS]
            lines.append(f"| {beta:g} | {prior:g} | " + " | ".join(f"{m:+.2f}" for m in means)
                         + " |")
    lines += ["", f"Per task at the defaults (beta {BANDWIDTHS[1]:g}, c {PRIORS[1]:g}):", "",
              "| task | " + " | ".join(KINDS) + " |", "|---|" + "---|" * len(KINDS)]
    for task in tasks:
        values = per_task[task][BANDWIDTHS[1], PRIORS[1]]
        lines.append(f"| {task} | " + " | ".join(f"{values[kind]:+.2f}" for kind in KINDS)
                     + " |")
    output = Path(__file__).with_name("certainty_calibration.md")
    output.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
