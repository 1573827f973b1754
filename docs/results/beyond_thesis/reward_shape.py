"""The shape of the finetuned directional reward: D3 against d_certainty and D3 scaled by the
certainty (``reward.certainty_scaling``), the thesis's section 6.4 question ("is the indicator
shape of D3 desirable?"), measured offline.

For each task, on the reward-quality benchmark's datasets, split and finetuning (1,000 updates by
default, the benchmark's ``finetune.*`` and ``reward.*`` settings), the reward the agent would get
at every held-out step (successful episodes up to their first success, failed episodes whole):

- saturated: the fraction of steps with |r_D| > 0.9 (D3 behaves like an indicator: near +-1);
- mean r_D on successful and on failed steps;
- direction accuracy and AUROC as the benchmark computes them, but of the reward the agent sees:
  with the certainty scaling that is |t(s_t, Δs_t)| r_D3, which the benchmark's own scoring (it
  scores ``directional_reward``, the heads' output) does not include.

    OMP_NUM_THREADS=1 python docs/results/beyond_thesis/reward_shape.py \
        env.task=[drawer-open,door-open,window-open,window-close,push,button-press-topdown]

Writes ``docs/results/beyond_thesis/reward_shape.md``; overrides are
``recipes/evaluate_rewards.py``'s.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from torch import Tensor

from temporal_torchrl.configs.rules import (
    config_tasks,
    resolve_device,
    validate_reward_quality_config,
)
from temporal_torchrl.machine import machine_description
from temporal_torchrl.reward_quality import (
    auroc,
    direction_accuracy,
    episode_embeddings,
    finetune_reward,
    make_finetuning_buffer,
    prepare_task,
    state_rewards,
    success_length,
    task_config,
)
from temporal_torchrl.rewards import TemporalReward, single_part
from temporal_torchrl.rewards.registry import declared_options
from temporal_torchrl.training import factories

#: The recipes' config folder, whose ``evaluate_rewards.yaml`` the study composes.
RECIPES = Path(__file__).resolve().parents[3] / "recipes"

#: (label, variant, certainty scaling)
CONFIGURATIONS = (("d3", "d3", False), ("d_certainty", "d_certainty", False),
                  ("d3 x certainty", "d3", True))
COLUMNS = ("saturated", "mean r_D successful", "mean r_D failed", "direction accuracy", "AUROC")


@torch.no_grad()
def agent_rewards(reward: TemporalReward, states: Tensor) -> Tensor:
    """The r_D the agent sees at every state of one episode (s_0 first), scaled by |t| with
    ``certainty_scaling``, as ``TemporalReward.forward`` computes it."""
    rewards = state_rewards(reward, states)
    if reward.certainty is not None:
        previous = states[(torch.arange(states.shape[0]) - reward.k).clamp_min(0)]
        rewards = rewards * reward.certainty(states, states - previous).abs()
    return rewards


def shape(reward: TemporalReward, successful, failed) -> dict[str, float]:
    positive, negative, forward, backward = [], [], [], []
    for episode in successful:
        length = success_length(episode)
        states = episode_embeddings(episode)[:length + 1]
        rewards = agent_rewards(reward, states)
        positive.append(rewards[1:])
        forward.append(rewards[1:length])
        backward.append(agent_rewards(reward, states.flip(0)).flip(0)[1:length])
    for episode in failed:
        negative.append(agent_rewards(reward, episode_embeddings(episode))[1:])
    positive, negative = torch.cat(positive), torch.cat(negative)
    every = torch.cat([positive, negative])
    return {"saturated": float((every.abs() > 0.9).float().mean()),
            "mean r_D successful": float(positive.mean()),
            "mean r_D failed": float(negative.mean()),
            "direction accuracy": direction_accuracy(torch.cat(forward), torch.cat(backward)),
            "AUROC": auroc(positive, negative)}


def task_shapes(cfg, encoder) -> dict[str, dict[str, float]]:
    data = prepare_task(cfg, encoder)
    train, successful, failed = data.train, data.successful, data.failed
    goal_image, texts = data.goal_image, (data.goal_embedding, data.baseline_embedding)
    buffer = make_finetuning_buffer(train.episodes, stage=cfg.finetune.stage,
                                    k=cfg.reward.k, label_window=cfg.reward.label_window,
                                    gap=cfg.reward.gap)
    shapes = {}
    for label, variant, scaling in CONFIGURATIONS:
        torch.manual_seed(cfg.env.seed)
        # The certainty options (reward.options) of those that read them.
        declared = declared_options([variant], scaling)
        reward = TemporalReward(encoder.dim, texts[0], texts[1], **single_part(variant),
                                k=cfg.reward.k, certainty_scaling=scaling,
                                options={key: value for key, value in cfg.reward.options.items()
                                         if key in declared})
        finetune_reward(reward, buffer, goal_image, updates=cfg.finetune.updates,
                        batch_size=cfg.reward.batch_size, lr=cfg.reward.lr)
        shapes[label] = shape(reward, successful, failed)
        print(f"  {cfg.env.task} {label}: " + ", ".join(
            f"{key} {value:.2f}" for key, value in shapes[label].items()), flush=True)
    return shapes


def main(overrides: list[str]) -> None:
    torch.set_num_threads(1)
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("evaluate_rewards", overrides=overrides)
    cfg = validate_reward_quality_config(cfg)
    start = time.perf_counter()
    encoder = factories.make_encoder(cfg, resolve_device(cfg.encoder.device))
    tasks = config_tasks(cfg)
    per_task = {task: task_shapes(task_config(cfg, task), encoder)
                for task in tasks}
    lines = ["# The shape of the finetuned directional reward: D3, d_certainty, D3 x certainty",
             "", f"Held-out steps of the reward-quality benchmark ({encoder.name} encoder, "
             f"{cfg.finetune.updates} updates, stage {cfg.finetune.stage}); the reward the agent "
             "sees (with the certainty scaling: |t| r_D3). 'saturated': fraction of steps with "
             "|r_D| > 0.9. Mean over the tasks, then per task.", "",
             "| reward | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
    for label, _, _ in CONFIGURATIONS:
        means = [sum(per_task[task][label][column] for task in tasks) / len(tasks)
                 for column in COLUMNS]
        lines.append(f"| {label} | " + " | ".join(f"{value:+.2f}" if "mean" in column
                                                  else f"{value:.2f}"
                                                  for column, value in zip(COLUMNS, means,
                                                                           strict=True)) + " |")
    for task in tasks:
        lines += ["", f"**{task}**", "", "| reward | " + " | ".join(COLUMNS) + " |",
                  "|---|" + "---|" * len(COLUMNS)]
        for label, _, _ in CONFIGURATIONS:
            values = per_task[task][label]
            lines.append(f"| {label} | " + " | ".join(
                f"{values[column]:+.2f}" if "mean" in column else f"{values[column]:.2f}"
                for column in COLUMNS) + " |")
    lines += ["", f"- command: `python docs/results/beyond_thesis/reward_shape.py "
              f"{' '.join(overrides)}`",
              f"- machine: {machine_description()}; wall time "
              f"{time.perf_counter() - start:.0f} s"]
    output = Path(__file__).with_name("reward_shape.md")
    output.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
