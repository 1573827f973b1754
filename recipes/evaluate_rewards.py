"""Offline reward-quality benchmark: score every reward variant for a task and an encoder.

For each task: collect (or load from the cache) embedded successful expert episodes and failed
episodes (uniform random actions, heavily noised experts), split them by episode into a training
and a held-out part, then for each reward variant score the rewards on the held-out part before
and after finetuning its heads offline on the training part with the package's own losses:

- positional variants: value-order correlation (VOC) along successful episodes and AUROC of the
  per-step reward, successful against failed steps;
- directional variants: direction accuracy (real order against the episode played backwards)
  and AUROC;
- zero-shot variants (``liv``): the same, without heads.

    python recipes/evaluate_rewards.py                                   # drawer-open, all variants
    python recipes/evaluate_rewards.py env.task=door-open finetune.updates=2000
    python recipes/evaluate_rewards.py encoder.name=liv encoder.checkpoint=/path/to/model.pt
    python recipes/evaluate_rewards.py reward.modules=[my_rewards.py] reward.positional=[furl,p5]
    python recipes/evaluate_rewards.py reward.directional=[d3,d_certainty,d_sequence]
    python recipes/evaluate_rewards.py \
        env.task=[drawer-open,door-open,window-open,window-close,push,button-press-topdown]

Outputs in ``<output_dir>/<task>/``: ``results.md``, ``results.json`` and ``figures/<variant>.png``
(the reward along one held-out successful and one failed episode, as the thesis's Figure 5.12);
with several tasks also ``<output_dir>/summary.md`` and ``summary.json``.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from temporal_torchrl.configs.rules import (
    config_tasks,
    config_variants,
    resolve_device,
    validate_reward_quality_config,
)
from temporal_torchrl.data import EpisodeReplayBuffer
from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs import baseline_text, get_task
from temporal_torchrl.machine import machine_description
from temporal_torchrl.reward_quality import (
    dataset_spec,
    finetune_reward,
    make_finetuning_buffer,
    outputs,
    prepare_task,
    reward_curve,
    score_reward,
    success_length,
    task_config,
)
from temporal_torchrl.rewards import reward_from_config
from temporal_torchrl.runs import write_json
from temporal_torchrl.training import factories


# --------------------------------------------------------------------------- one task
def evaluate_task(cfg: DictConfig, encoder: Encoder, command: str) -> dict:
    """Collect or load the task's dataset, then score every variant; returns the result dict
    (:mod:`temporal_torchrl.reward_quality.outputs`) and writes it under ``output_dir/<task>``."""
    start = time.perf_counter()
    task = get_task(cfg.env.task)
    data = prepare_task(cfg, encoder)
    dataset, train, held_out = data.dataset, data.train, data.held_out
    successful, failed, goal_image = data.successful, data.failed, data.goal_image
    goal_embedding, baseline_embedding = data.goal_embedding, data.baseline_embedding
    dataset_seconds = time.perf_counter() - start
    # The figure's failed episode: a failed expert when there is one (it approaches the goal
    # for a while, like the thesis's Figure 5.12 negative), else any failed episode.
    failed_kinds = [kind for kind, ok in zip(held_out.kinds, held_out.successful, strict=True)
                    if not ok]
    figure_failed = failed[failed_kinds.index("failed_expert")] \
        if "failed_expert" in failed_kinds else failed[0]
    figure_successful = successful[0]

    # One buffer per window length (None for every reward that reads no window).
    buffers: dict[int | None, EpisodeReplayBuffer] = {}

    output = Path(cfg.output_dir) / task.name
    rows = []
    for variant in config_variants(cfg):
        variant_start = time.perf_counter()
        torch.manual_seed(cfg.env.seed)  # the same initial heads whatever the variant order
        reward = reward_from_config(cfg, goal_embedding, baseline_embedding, variant=variant)
        has_heads = (reward.positional_heads is not None
                     or reward.directional_heads is not None)
        states = ["untrained", "finetuned"] if has_heads else ["zero-shot"]
        curves: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}
        final_losses: dict[str, float] = {}
        for state in states:
            if state == "finetuned":
                if reward.window_length not in buffers:
                    buffers[reward.window_length] = make_finetuning_buffer(
                        train.episodes, stage=cfg.finetune.stage, k=cfg.reward.k,
                        label_window=cfg.reward.label_window, window_length=reward.window_length,
                        gap=cfg.reward.gap)
                final_losses = finetune_reward(
                    reward, buffers[reward.window_length], goal_image,
                    updates=cfg.finetune.updates,
                    batch_size=cfg.reward.batch_size, lr=cfg.reward.lr,
                    delta=cfg.reward.delta, l2_margin=cfg.reward.l2_margin,
                    same_position=cfg.reward.same_position)
            scores = score_reward(reward, successful, failed)
            rows.append({"variant": variant, "kind": scores.kind, "heads": state,
                         "options": reward.options,
                         "value_order_correlation": scores.value_order_correlation,
                         "value_order_correlation_std": scores.value_order_correlation_std,
                         "direction_accuracy": scores.direction_accuracy,
                         "auroc": scores.auroc,
                         "final_losses": final_losses if state == "finetuned" else {},
                         "seconds": time.perf_counter() - variant_start})
            curves[state] = (reward_curve(reward, figure_successful),
                             reward_curve(reward, figure_failed))
        if cfg.figures:
            # The trained (or zero-shot) curve first, solid; the untrained one dashed.
            order = list(reversed(states))
            outputs.plot_variant_curves(
                output / "figures" / f"{variant}.png",
                f"{task.name}: {variant} ({scores.kind}, {order[0]}), {encoder.name}, "
                "held-out episodes",
                {state: curves[state][0] for state in order},
                {state: curves[state][1] for state in order},
                success_step=success_length(figure_successful),
                ylabel=f"r_{'P' if scores.kind == 'positional' else 'D'}")
        print(f"  {task.name} {variant}: " + "; ".join(
            f"{row['heads']} {outputs.metric_text(row)}" for row in rows
            if row["variant"] == variant) + f" ({rows[-1]['seconds']:.0f} s)", flush=True)

    result = {
        "task": task.name, "goal": task.goal_prompt,
        "baseline": baseline_text(cfg.env.task, cfg.reward.baseline),
        "encoder": {"name": encoder.name, "dim": encoder.dim,
                    "checkpoint": cfg.encoder.checkpoint,
                    "options": OmegaConf.to_container(cfg.encoder.options, resolve=True) or {},
                    "description": factories.describe_encoder(cfg, encoder)},
        "dataset": {"spec": dataclasses.asdict(dataset_spec(cfg)),
                    "held_out_fraction": cfg.dataset.held_out_fraction,
                    "train": train.describe(), "held_out": held_out.describe(),
                    "failure_noise": dataset.describe()["failed_expert"]["noise"],
                    "collection_seconds": dataset.collection_seconds,
                    "source": dataset.source},
        "finetuning": {"stage": cfg.finetune.stage, "updates": cfg.finetune.updates,
                       **{key: cfg.reward[key] for key in (
                           "batch_size", "lr", "delta", "l2_margin", "gap", "same_position",
                           "label_window", "k", "alpha", "projection")},
                       "options": OmegaConf.to_container(cfg.reward.options, resolve=True)},
        "run": {"command": command, "machine": machine_description(),
                "seconds": time.perf_counter() - start, "dataset_seconds": dataset_seconds,
                "scoring_seconds": time.perf_counter() - start - dataset_seconds},
        "rows": rows,
    }
    output.mkdir(parents=True, exist_ok=True)
    write_json(output / "results.json", result)
    (output / "results.md").write_text(outputs.results_markdown(result))
    return result


# --------------------------------------------------------------------------- all tasks
def evaluate(cfg: DictConfig, command: str | None = None) -> list[dict]:
    """Score every configured variant on every configured task; returns one result per task.

    ``command`` is recorded in the results (default: the recipe's name, for configs built in
    code).
    """
    cfg = validate_reward_quality_config(cfg)
    if cfg.threads is not None:
        torch.set_num_threads(cfg.threads)
    command = command or "python recipes/evaluate_rewards.py (config composed in code)"
    encoder = factories.make_encoder(cfg, resolve_device(cfg.encoder.device))
    print(factories.describe_encoder(cfg, encoder), flush=True)
    results = []
    for task in config_tasks(cfg):
        results.append(evaluate_task(task_config(cfg, task), encoder, command))
        print(f"{task}: {results[-1]['run']['seconds']:.0f} s -> "
              f"{Path(cfg.output_dir) / task / 'results.md'}", flush=True)
    if len(results) > 1:
        output = Path(cfg.output_dir)
        write_json(output / "summary.json", {"tasks": results})
        (output / "summary.md").write_text(outputs.summary_markdown(results))
        print(f"summary -> {output / 'summary.md'}", flush=True)
    return results


@hydra.main(config_path=".", config_name="evaluate_rewards", version_base=None)
def main(cfg: DictConfig) -> None:
    overrides = HydraConfig.get().overrides.task
    evaluate(cfg, " ".join(["python recipes/evaluate_rewards.py", *overrides]))


if __name__ == "__main__":
    main()
