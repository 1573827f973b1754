"""Pretrain the small Metaworld vision-language encoder with LIV's objective, then evaluate it.

Steps (one command, one seed; defaults reproduce the shipped ``metaworld_small`` weights):

1. Data: scripted-expert videos of the 44 MT50 tasks that are not evaluation tasks (the six
   evaluation tasks stay held out), at several action-noise levels and layouts, rendered at
   the encoder's input size from the ``corner2`` camera; unsuccessful episodes are dropped.
   Each video is paired with its task's goal prompt (``TASKS[task].goal_prompt``).
2. Training: :class:`~temporal_torchrl.objectives.liv.LIVLoss` (VIP value objective with the
   last frame and with the goal text as goals, plus goal-frame/text InfoNCE) on batches of
   (start, t, t+1, goal) frames sampled from random videos, with random-shift augmentation.
3. Evaluation (``recipes/evaluate_encoder.py``): zero-shot value-order correlation on the six
   held-out tasks for the trained encoder, the same architecture with random weights and
   random-weight LIV (and released LIV with ``--liv-checkpoint``).
4. Output: ``<output-dir>/<name>.pt`` (float16 state dict + config, loadable with
   ``torch.load(weights_only=True)``) and ``<output-dir>/MODEL_CARD.md``.

Usage:
    python recipes/pretrain_encoder.py                 # writes temporal_torchrl/encoders/weights/
    python recipes/pretrain_encoder.py --steps 200 --episodes-per-noise 1 --output-dir /tmp/enc

Train on your own robot videos by replacing :func:`collect_training_videos` with a loader that
returns the same :class:`VideoDataset` (uint8 frames, one text per video).
"""

from __future__ import annotations

import argparse
import math
import os
import random
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import temporal_torchrl  # noqa: F401  (chooses the GL backend before mujoco loads)
from temporal_torchrl.encoders.small import WEIGHTS_DIR, SmallEncoder
from temporal_torchrl.envs import EVALUATION_TASKS, TASKS, collect_expert_episodes
from temporal_torchrl.machine import machine_description
from temporal_torchrl.objectives.liv import LIVLoss
from temporal_torchrl.reward_quality.encoder_evaluation import (
    collect_evaluation_videos,
    default_encoders,
    episode_frames,
    evaluate_encoders,
    markdown_table,
)


@dataclass
class VideoDataset:
    """Videos stored back to back: ``frames[starts[i] : starts[i] + lengths[i]]`` is video i."""

    frames: torch.Tensor  # uint8 [N, H, W, 3]
    starts: torch.Tensor  # int64 [V]
    lengths: torch.Tensor  # int64 [V]
    text_ids: torch.Tensor  # int64 [V], index into texts
    texts: list[str]

    @property
    def num_videos(self) -> int:
        return len(self.starts)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--name", default="metaworld_small", help="weights file name")
    parser.add_argument("--output-dir", default=str(WEIGHTS_DIR))
    parser.add_argument("--image-size", type=int, default=64)
    parser.add_argument("--embedding-dim", type=int, default=256)
    parser.add_argument("--tasks", nargs="+", default=None,
                        help="training tasks (default: every MT50 task but the evaluation tasks)")
    parser.add_argument("--noise-levels", type=float, nargs="+", default=[0.1, 0.3])
    parser.add_argument("--episodes-per-noise", type=int, default=2,
                        help="episodes per task and noise level (each with its own layout)")
    parser.add_argument("--max-episode-steps", type=int, default=250,
                        help="expert episodes that have not succeeded by then are dropped")
    parser.add_argument("--steps", type=int, default=600, help="optimiser steps")
    parser.add_argument("--batch-size", type=int, default=16, help="videos per batch")
    parser.add_argument("--pairs-per-video", type=int, default=4,
                        help="consecutive (t, t+1) pairs sampled from each video of a batch")
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--weight-decay", type=float, default=1e-4)
    parser.add_argument("--gamma", type=float, default=0.98)
    parser.add_argument("--value-scale", type=float, default=10.0,
                        help="V = scale * cosine in the loss (1 is LIV's; see LIVLoss)")
    parser.add_argument("--temperature", type=float, default=0.1)
    parser.add_argument("--image-goal-weight", type=float, default=1.0)
    parser.add_argument("--text-goal-weight", type=float, default=1.0)
    parser.add_argument("--contrastive-weight", type=float, default=1.0)
    parser.add_argument("--shift", type=int, default=4, help="random-shift augmentation (pixels)")
    parser.add_argument("--log-every", type=int, default=100, help="steps between log lines")
    parser.add_argument("--eval-episodes", type=int, default=3)
    parser.add_argument("--liv-checkpoint", default=None, help="adds released LIV to the table")
    parser.add_argument("--no-random-liv", action="store_true", help="skip the random RN50 row")
    parser.add_argument("--data-cache", default=None,
                        help="save the generated training videos here, or reuse them if present")
    parser.add_argument("--threads", type=int, default=2)
    return parser.parse_args(argv)


def collect_training_videos(args: argparse.Namespace) -> VideoDataset:
    """Successful expert videos of every non-evaluation MT50 task at each noise level."""
    tasks = args.tasks or [task for task in TASKS if task not in EVALUATION_TASKS]
    for task in tasks:
        if task not in TASKS or task in EVALUATION_TASKS:
            raise ValueError(
                f"training task {task!r} is not allowed: expected an MT50 task name that is not "
                f"an evaluation task ({', '.join(EVALUATION_TASKS)}), e.g. 'drawer-close'."
            )
    frames, starts, lengths, text_ids, offset = [], [], [], [], 0
    for task_index, task in enumerate(tasks):
        for noise_index, noise in enumerate(args.noise_levels):
            for episode_index in range(args.episodes_per_noise):
                # Every episode gets its own layout (env seed) and noise stream.
                layout = args.seed + noise_index * args.episodes_per_noise + episode_index
                episode, = collect_expert_episodes(
                    task, seed=layout, num_episodes=1, noise=noise, render=True,
                    image_size=args.image_size, max_episode_steps=args.max_episode_steps,
                    generator_seed=layout)
                if not episode["next", "success"].any():
                    continue
                video = episode_frames(episode)
                frames.append(video)
                starts.append(offset)
                lengths.append(len(video))
                text_ids.append(task_index)
                offset += len(video)
        print(f"  data: {task} done, {len(starts)} videos, {offset} frames so far", flush=True)
    return VideoDataset(torch.cat(frames), torch.tensor(starts), torch.tensor(lengths),
                        torch.tensor(text_ids), [TASKS[task].goal_prompt for task in tasks])


def load_or_collect(args: argparse.Namespace) -> tuple[VideoDataset, float]:
    """The training videos and the seconds their generation took (read back from the cache)."""
    cache = Path(args.data_cache) if args.data_cache else None
    if cache is not None and cache.is_file():
        payload = torch.load(cache, weights_only=True)
        return VideoDataset(**payload["dataset"]), float(payload["seconds"])
    start = time.perf_counter()
    dataset = collect_training_videos(args)
    seconds = time.perf_counter() - start
    if cache is not None:
        torch.save({"dataset": dataset.__dict__, "seconds": seconds}, cache)
    return dataset, seconds


def random_shift(images: torch.Tensor, shift: int, generator: torch.Generator,
                 group_size: int = 1) -> torch.Tensor:
    """Translate images ``[B, C, S, S]`` by up to ``shift`` pixels (edge padding, DrQ).

    Each run of ``group_size`` consecutive images (the frames of one sampled video) gets the
    same translation, as VIP augments a sample's frames together: otherwise the difference
    between frames t and t+1 would be mostly augmentation.
    """
    if shift == 0:
        return images
    batch, channels, size, _ = images.shape
    padded = torch.nn.functional.pad(images, (shift,) * 4, mode="replicate")
    offsets = torch.randint(0, 2 * shift + 1, (2, batch // group_size), generator=generator)
    offsets = offsets.repeat_interleave(group_size, dim=1)
    base = torch.arange(size)
    rows = (base[None] + offsets[0, :, None])[:, None, :, None].expand(
        batch, channels, size, size + 2 * shift)
    padded = padded.gather(2, rows)
    columns = (base[None] + offsets[1, :, None])[:, None, None, :].expand(
        batch, channels, size, size)
    return padded.gather(3, columns)


def sample_batch(dataset: VideoDataset, batch_size: int, pairs_per_video: int,
                 generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Frame indices ``[B, pairs_per_video + 3]`` and text ids ``[B]`` of ``B`` random videos.

    Row ``b`` is (segment start ``s``, frames ``t .. t + W``, last frame ``T``) with
    ``W = pairs_per_video``: VIP's sampler (``s`` uniform in the video, ``(t, t + 1)`` after
    ``s``, goal the last frame), except that ``W`` consecutive pairs share one start and goal,
    which gives ``W`` value pairs for ``W + 3`` embedded frames instead of ``4 W``.
    """
    videos = torch.randint(0, dataset.num_videos, (batch_size,), generator=generator)
    last = dataset.lengths[videos] - 1
    latest_window = (last - pairs_per_video).clamp_min(0)
    start = (torch.rand(batch_size, generator=generator) * (latest_window + 1)).long()
    window = start + (torch.rand(batch_size, generator=generator)
                      * (latest_window - start + 1)).long()
    window = window[:, None] + torch.arange(pairs_per_video + 1)
    indices = torch.cat([start[:, None], window.minimum(last[:, None]), last[:, None]], dim=1)
    return indices + dataset.starts[videos, None], dataset.text_ids[videos]


def train(encoder: SmallEncoder, dataset: VideoDataset, args: argparse.Namespace
          ) -> list[dict[str, float]]:
    """Optimise ``encoder`` with :class:`LIVLoss`; returns metrics logged every 100 steps."""
    generator = torch.Generator().manual_seed(args.seed)
    loss_module = LIVLoss(gamma=args.gamma, value_scale=args.value_scale,
                          temperature=args.temperature,
                          image_goal_weight=args.image_goal_weight,
                          text_goal_weight=args.text_goal_weight,
                          contrastive_weight=args.contrastive_weight)
    token_table = encoder.text_encoder.token_embedding.weight
    dense = [p for p in encoder.parameters() if p is not token_table]
    optimizers = [torch.optim.AdamW(dense, lr=args.learning_rate, weight_decay=args.weight_decay),
                  torch.optim.SparseAdam([token_table], lr=args.learning_rate)]

    def schedule(step: int) -> float:
        return min(1.0, (step + 1) / 100) * 0.5 * (1.0 + math.cos(math.pi * step / args.steps))

    schedulers = [torch.optim.lr_scheduler.LambdaLR(o, schedule) for o in optimizers]
    tokens = encoder.text_encoder.tokenize(dataset.texts)
    pairs = args.pairs_per_video
    encoder.image_encoder.train()  # BatchNorm statistics (Encoder.train() would keep it in eval)
    history, running, start_time = [], {}, time.perf_counter()
    for step in range(1, args.steps + 1):
        indices, text_ids = sample_batch(dataset, args.batch_size, pairs, generator)
        frames = dataset.frames[indices.flatten()]
        images = random_shift(encoder.image_encoder.preprocess(frames), args.shift, generator,
                              group_size=indices.shape[1])
        embeddings = encoder.image_encoder(images).unflatten(0, indices.shape)
        initial, window, goal = embeddings[:, 0], embeddings[:, 1:-1], embeddings[:, -1]
        text = encoder.text_encoder(tokens)[text_ids]

        def per_pair(x: torch.Tensor) -> torch.Tensor:
            return x.repeat_interleave(pairs, dim=0)

        losses = loss_module(per_pair(initial), window[:, :-1].flatten(0, 1),
                             window[:, 1:].flatten(0, 1), per_pair(goal), per_pair(text),
                             task_ids=per_pair(text_ids))
        for optimizer in optimizers:
            optimizer.zero_grad(set_to_none=True)
        losses["loss"].backward()
        for optimizer, scheduler in zip(optimizers, schedulers, strict=True):
            optimizer.step()
            scheduler.step()
        for key, value in losses.items():
            running[key] = running.get(key, 0.0) + value.item()
        if step % args.log_every == 0 or step == args.steps:
            count = args.log_every if step % args.log_every == 0 else step % args.log_every
            record = {"step": step, "seconds": time.perf_counter() - start_time}
            record.update({key: value / count for key, value in running.items()})
            history.append(record)
            running = {}
            print("  train: " + ", ".join(f"{k} {v:.4g}" for k, v in record.items()), flush=True)
    encoder.freeze()
    encoder.clear_text_cache()
    return history


def write_model_card(path: Path, args: argparse.Namespace, dataset: VideoDataset,
                     encoder: SmallEncoder, timings: dict[str, float], history: list[dict],
                     rows: list[dict], weights_path: Path) -> None:
    # --data-cache only saves or reuses the generated videos and --output-dir only says where
    # the files go: neither changes the result, so the reproduce command leaves them out.
    arguments, skip = [], False
    for argument in sys.argv[1:]:
        if skip:
            skip = False
        elif argument in ("--data-cache", "--output-dir"):
            skip = True
        elif not argument.startswith(("--data-cache=", "--output-dir=")):
            arguments.append(argument)
    command = " ".join(["python recipes/pretrain_encoder.py", *map(shlex.quote, arguments)])
    parameters = sum(p.numel() for p in encoder.parameters())
    last = history[-1]
    size, dim = args.image_size, args.embedding_dim
    layouts = f"{args.seed}..{args.seed + len(args.noise_levels) * args.episodes_per_noise - 1}"
    data_note = (" (generation time of an earlier run with the same data settings, whose "
                 "--data-cache file this run read back)") if timings["data_cached"] else ""
    card = f"""# Model card: `{args.name}`

A small vision-language encoder for Metaworld, trained by this project with LIV's objective so
that the package runs offline and fast on a CPU. Load it with
`temporal_torchrl.encoders.load_encoder("{args.name}")`.

## Architecture
- Image tower: CNN of 5 convolutions with ReLU (stride-2 stages of 32, 64 (+1 conv), 128 and
  128 channels) on {size}x{size} RGB frames, flattened {size // 16}x{size // 16} map -> MLP ->
  {dim}-d embedding. Frames of another size are resized by the encoder (bilinear,
  antialiased); render at {size}x{size} to skip that.
- Text tower: open_clip's `RN50-quickgelu` tokenizer (CLIP BPE), mean of learnt 64-d token
  embeddings (start, end and padding tokens ignored) -> MLP -> {dim}-d embedding.
- Similarity: cosine, as LIV. Embeddings are not L2-normalised.
- {parameters / 1e6:.2f} M parameters (3.16 M of them the token table), stored in float16
  ({weights_path.stat().st_size / 1e6:.1f} MB), read with `torch.load(..., weights_only=True)`.

## Data
- Scripted Metaworld experts (`collect_expert_episodes`: goal-hidden fixed-goal envs, camera
  `corner2`, frames rendered at {size}x{size}) on the {len(dataset.texts)} MT50 tasks that are
  not evaluation tasks. The six evaluation tasks ({", ".join(EVALUATION_TASKS)}) are held out
  entirely: no frames, no prompts.
- Action noise levels {args.noise_levels}, {args.episodes_per_noise} episodes per task and
  level, each episode its own layout (env seeds {layouts}); episodes end 5 steps after the
  first success; episodes without a success within {args.max_episode_steps} steps are dropped.
- {dataset.num_videos} videos, {len(dataset.frames)} frames. A video's text is its task's
  goal prompt (`TASKS[task].goal_prompt`).

## Objective
`temporal_torchrl.objectives.liv.LIVLoss` (its docstring gives the equations and assumptions):
VIP's value objective with the cosine value V(o; g) = cos(phi(o), e_g), gamma = {args.gamma},
with the last frame as goal (weight {args.image_goal_weight}) and with the goal text as goal
(weight {args.text_goal_weight}), plus a symmetric goal-frame/text InfoNCE (temperature
{args.temperature}, weight {args.contrastive_weight}; videos of the same task are positives of
each other). A batch holds {args.batch_size} videos, each giving a segment start,
{args.pairs_per_video} consecutive (t, t+1) pairs and its last frame; random shifts of up to
{args.shift} pixels.

## Training
- {args.steps} steps of AdamW (sparse Adam for the token table), learning rate
  {args.learning_rate} (100-step warm-up, cosine decay), weight decay {args.weight_decay},
  seed {args.seed}, {args.threads} CPU threads.
- Wall time: data {timings["data"]:.0f} s{data_note}, training {timings["train"]:.0f} s,
  evaluation {timings["evaluation"]:.0f} s, on {timings["machine"]}; 1-minute load average
  {timings["load_start"]:.2f} before training and {timings["load_end"]:.2f} at its end (this
  run's own threads included).
- Last logged training metrics (mean over its last {args.log_every} steps): loss {last["loss"]:.4f},
  VIP image goal {last["loss_vip_image"]:.4f}, VIP text goal {last["loss_vip_text"]:.4f},
  InfoNCE {last["loss_contrastive"]:.4f}; fraction of (t, t+1) pairs whose value increases:
  image goal {last["value_increase_image"]:.3f}, text goal {last["value_increase_text"]:.3f}.

## Zero-shot evaluation on the six held-out tasks
Spearman rank correlation between the frame index and csim(frame embedding, goal-prompt
embedding) along scripted-expert episodes (layout seed {args.seed}, action noise 0.1, every
frame up to 5 steps after the first success), averaged over the episodes of a task; per task
and mean. "mean image-goal rho" uses the episode's last frame as the goal instead of the
prompt (the goal frame itself left out). Small-encoder rows: {args.eval_episodes} episodes per
task rendered at {size}x{size}. LIV RN50 rows: the first {min(2, args.eval_episodes)} of those
episodes rendered at 224x224, every 4th frame (RN50 embeds a few frames per second on a CPU).
Random-weight LIV is open_clip `RN50-quickgelu` with random weights written in LIV's checkpoint
format and read by `load_encoder("liv", checkpoint=...)`.

{markdown_table(rows)}

## Intended use and limits
The offline, CPU-fast default encoder of the package's reward-shaping pipeline on Metaworld
(corner2 camera, {size}x{size} renders). Trained only on scripted-expert videos of 44 simulated
tasks with one prompt per task: its text tower knows only the words of those prompts (unseen
words get untrained embeddings), and it is no general-purpose vision-language model. For the
thesis's results use LIV (`load_encoder("liv")`).

## Reproduce
```
{command}
```
Data generation is deterministic; training on a CPU with the same thread count reproduces the
numbers up to the nondeterminism of multithreaded floating-point kernels.
"""
    path.write_text(card)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.liv_checkpoint is not None and not Path(args.liv_checkpoint).is_file():
        raise SystemExit(f"--liv-checkpoint {args.liv_checkpoint!r} is not a file: pass the path "
                         "of LIV's model.pt (https://huggingface.co/jasonyma/LIV), or leave the "
                         "flag out.")
    torch.set_num_threads(args.threads)
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    timings = {"machine": machine_description()}
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)

    print("1/4 collecting training videos", flush=True)
    timings["data_cached"] = bool(args.data_cache) and Path(args.data_cache).is_file()
    dataset, timings["data"] = load_or_collect(args)
    print(f"  {dataset.num_videos} videos, {len(dataset.frames)} frames, "
          f"{timings['data']:.0f} s", flush=True)

    print("2/4 training", flush=True)
    torch.manual_seed(args.seed)
    encoder = SmallEncoder(image_size=args.image_size, embedding_dim=args.embedding_dim,
                           name=args.name)
    timings["load_start"] = os.getloadavg()[0]
    start = time.perf_counter()
    history = train(encoder, dataset, args)
    timings["train"] = time.perf_counter() - start
    timings["load_end"] = os.getloadavg()[0]
    weights_path = output_dir / f"{args.name}.pt"
    encoder.save(weights_path)

    print("3/4 evaluating on the held-out tasks", flush=True)
    start = time.perf_counter()
    small_videos = collect_evaluation_videos(args.image_size, args.eval_episodes, args.seed)
    need_large = not args.no_random_liv or args.liv_checkpoint
    large_videos = collect_evaluation_videos(224, min(2, args.eval_episodes), args.seed) \
        if need_large else {}
    rows = evaluate_encoders(default_encoders(str(weights_path), args.liv_checkpoint, args.seed,
                                              not args.no_random_liv),
                             small_videos, large_videos, large_stride=4)
    timings["evaluation"] = time.perf_counter() - start

    print("4/4 writing the model card", flush=True)
    write_model_card(output_dir / "MODEL_CARD.md", args, dataset, encoder, timings, history,
                     rows, weights_path)
    print(markdown_table(rows))
    print(f"weights: {weights_path}\nmodel card: {output_dir / 'MODEL_CARD.md'}")


if __name__ == "__main__":
    main()
