"""d_sequence's image head: the one-layer Transformer (the package's SequenceEncoder) against a
two-layer temporal convolution, measured three ways.

- parameters of the image head, for the shipped encoder's D = 256 and LIV's D = 1024 (K = 8);
- time of one head update (the directional loss on a batch of 256 negative and 256 positive
  windows, forward, backward and a fused Adam step), median of 30, one torch thread, next to D3's
  update on the same batch;
- reward quality on the offline benchmark (the datasets, split, finetuning and scoring of
  ``recipes/evaluate_rewards.py``): direction accuracy and AUROC after ``finetune.updates``.

    OMP_NUM_THREADS=1 python docs/results/beyond_thesis/sequence_encoders.py \
        env.task=[drawer-open,door-open,window-open,window-close,push,button-press-topdown]

Writes ``docs/results/beyond_thesis/sequence_encoders_updates<finetune.updates>.md``; overrides
are ``recipes/evaluate_rewards.py``'s (``finetune.updates=100`` for the learning speed).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torch import Tensor, nn

from temporal_torchrl.configs.rules import (
    config_tasks,
    resolve_device,
    validate_reward_quality_config,
)
from temporal_torchrl.machine import machine_description
from temporal_torchrl.objectives import finetuning_losses
from temporal_torchrl.reward_quality import (
    finetune_reward,
    make_finetuning_buffer,
    prepare_task,
    score_reward,
    task_config,
)
from temporal_torchrl.rewards import REWARDS, TemporalReward, single_part
from temporal_torchrl.training import factories

#: The recipes' config folder, whose ``evaluate_rewards.yaml`` the study composes.
RECIPES = Path(__file__).resolve().parents[3] / "recipes"

ENCODERS = ("transformer", "convolution")


class TemporalConvolution(nn.Module):
    """The alternative: Conv1d(2D -> 64, 3) ReLU Conv1d(64 -> 64, 3) ReLU over the K - 1
    tokens (padding 1: one output per token, in order), flattened into the heads' MLP
    64 (K - 1) -> 256 -> ReLU -> 64."""

    def __init__(self, token_dim: int, length: int, hidden_dim: int = 256, out_dim: int = 64,
                 width: int = 64):
        super().__init__()
        self.token_dim, self.length = token_dim, length
        self.convolution = nn.Sequential(
            nn.Conv1d(token_dim, width, 3, padding=1), nn.ReLU(),
            nn.Conv1d(width, width, 3, padding=1), nn.ReLU())
        self.output = nn.Sequential(nn.Linear(width * length, hidden_dim), nn.ReLU(),
                                    nn.Linear(hidden_dim, out_dim))

    def forward(self, tokens: Tensor) -> Tensor:
        batch = tokens.shape[:-2]
        hidden = self.convolution(tokens.reshape(-1, self.length, self.token_dim).transpose(1, 2))
        return self.output(hidden.flatten(1)).reshape(*batch, -1)


def sequence_reward(encoder: str, dim: int, goal: Tensor, baseline: Tensor,
                    window_length: int) -> TemporalReward:
    reward = TemporalReward(dim, goal, baseline, **single_part("d_sequence"),
                            options={"window": window_length})
    if encoder == "convolution":
        reward.directional_heads.image = TemporalConvolution(2 * dim, window_length - 1)
    return reward


def update_milliseconds(reward: TemporalReward, dim: int, window_length: int,
                        repeats: int = 30) -> float:
    """Median time of one head update on a random batch of 256 + 256 states."""
    def states() -> TensorDict:
        window = torch.randn(256, window_length, dim)
        return TensorDict({"embedding": window[:, -1], "previous_embedding": window[:, -6],
                           "initial_embedding": window[:, 0], "embedding_window": window}, [256])

    batch = TensorDict({"negative": states(), "positive": states()}, [256])
    loss, = finetuning_losses(reward, torch.randn(dim), stage=2)
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-4, fused=True)
    times = []
    for _ in range(repeats + 3):
        start = time.perf_counter()
        value = loss(batch)[loss.loss_key]
        optimizer.zero_grad(set_to_none=True)
        value.backward()
        optimizer.step()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times[3:])


def configured_window(cfg) -> int:
    """K: the config's ``reward.options.window``, else d_sequence's default."""
    return cfg.reward.options.get("window", REWARDS["d_sequence"].options["window"])


def task_scores(cfg, encoder) -> dict[str, tuple[float, float]]:
    """(direction accuracy, AUROC) of each image head after finetuning, on one task."""
    data = prepare_task(cfg, encoder)
    train, successful, failed = data.train, data.successful, data.failed
    goal_image, texts = data.goal_image, (data.goal_embedding, data.baseline_embedding)
    buffer = make_finetuning_buffer(train.episodes, stage=cfg.finetune.stage,
                                    k=cfg.reward.k, label_window=cfg.reward.label_window,
                                    window_length=configured_window(cfg), gap=cfg.reward.gap)
    scores = {}
    for name in ENCODERS:
        torch.manual_seed(cfg.env.seed)
        reward = sequence_reward(name, encoder.dim, texts[0], texts[1], configured_window(cfg))
        finetune_reward(reward, buffer, goal_image, updates=cfg.finetune.updates,
                        batch_size=cfg.reward.batch_size, lr=cfg.reward.lr)
        result = score_reward(reward, successful, failed)
        scores[name] = (result.direction_accuracy, result.auroc)
        print(f"  {cfg.env.task} {name}: direction accuracy {scores[name][0]:.3f}, AUROC "
              f"{scores[name][1]:.3f}", flush=True)
    return scores


def main(overrides: list[str]) -> None:
    torch.set_num_threads(1)
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("evaluate_rewards", overrides=overrides)
    cfg = validate_reward_quality_config(cfg)
    start = time.perf_counter()
    length = configured_window(cfg)
    lines = ["# d_sequence: Transformer or temporal convolution", "",
             f"K = {length} (K - 1 = {length - 1} tokens of 2D). Image-head parameters and the "
             "time of one head update (directional loss on 256 negative + 256 positive "
             "windows, forward + backward + fused Adam; median of 30, one torch thread), next "
             "to D3's update on the same batch.", "",
             "| image head | parameters, D = 256 | parameters, D = 1024 | ms / update, D = 256 "
             "| ms / update, D = 1024 |", "|---|---|---|---|---|"]
    goal, baseline = torch.randn(1024), torch.randn(1024)
    for name in (*ENCODERS, "d3 (MLP)"):
        parameters, milliseconds = [], []
        for dim in (256, 1024):
            torch.manual_seed(0)
            reward = (TemporalReward(dim, goal[:dim], baseline[:dim], positional=None,
                                     directional="d3") if name.startswith("d3") else
                      sequence_reward(name, dim, goal[:dim], baseline[:dim], length))
            parameters.append(sum(p.numel() for p in reward.directional_heads.image.parameters()))
            milliseconds.append(update_milliseconds(reward, dim, length))
        lines.append(f"| {name} | {parameters[0]:,} | {parameters[1]:,} | "
                     f"{milliseconds[0]:.1f} | {milliseconds[1]:.1f} |")
        print(lines[-1], flush=True)
    encoder = factories.make_encoder(cfg, resolve_device(cfg.encoder.device))
    tasks = config_tasks(cfg)
    per_task = {task: task_scores(task_config(cfg, task), encoder)
                for task in tasks}
    lines += ["", f"Reward quality after {cfg.finetune.updates} updates (stage "
              f"{cfg.finetune.stage}, batch {cfg.reward.batch_size}, lr {cfg.reward.lr}), "
              f"{encoder.name} encoder, held-out episodes of the reward-quality benchmark "
              "(direction accuracy / AUROC):", "",
              "| task | " + " | ".join(ENCODERS) + " |", "|---|" + "---|" * len(ENCODERS)]
    for task in tasks:
        lines.append(f"| {task} | " + " | ".join(
            f"{per_task[task][name][0]:.2f} / {per_task[task][name][1]:.2f}"
            for name in ENCODERS) + " |")
    means = {name: [sum(per_task[task][name][i] for task in tasks) / len(tasks)
                    for i in range(2)] for name in ENCODERS}
    lines.append("| mean | " + " | ".join(f"{means[name][0]:.2f} / {means[name][1]:.2f}"
                                          for name in ENCODERS) + " |")
    lines += ["", f"- command: `python docs/results/beyond_thesis/sequence_encoders.py "
              f"{' '.join(overrides)}`",
              f"- machine: {machine_description()}, shared with other jobs "
              f"(the update times are relative); wall time {time.perf_counter() - start:.0f} s"]
    output = Path(__file__).with_name(f"sequence_encoders_updates{cfg.finetune.updates}.md")
    output.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
