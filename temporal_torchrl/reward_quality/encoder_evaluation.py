"""Zero-shot value-order correlation of image/text encoders on the six held-out evaluation tasks.

For each evaluation task, expert episodes (frames o_0 .. o_T, the last a few steps after the
first success) are embedded, and two rank correlations are computed per episode:

- text-goal rho: Spearman correlation between the frame index t and
  ``csim(phi(o_t), psi(l_g))`` with ``l_g`` the task's goal prompt (LIV's zero-shot reward);
- image-goal rho: the same with the episode's last frame as the goal, ``csim(phi(o_t), phi(o_T))``.

An encoder whose similarity rises monotonically along successful episodes scores 1.
``recipes/evaluate_encoder.py`` runs it; ``recipes/pretrain_encoder.py`` calls
:func:`evaluate_encoders` at its end. Unlike the rest of :mod:`temporal_torchrl.reward_quality`
it scores encoders alone, without a reward's heads.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from scipy.stats import spearmanr
from tensordict import TensorDictBase

from temporal_torchrl.encoders import (
    Encoder,
    SmallEncoder,
    load_encoder,
    save_random_liv_checkpoint,
)
from temporal_torchrl.envs import EVALUATION_TASKS, TASKS, collect_expert_episodes


def episode_frames(episode: TensorDictBase) -> torch.Tensor:
    """All frames o_0 .. o_T of a rendered episode: uint8 ``[T + 1, H, W, 3]``."""
    return torch.cat([episode["pixels"], episode["next", "pixels"][-1:]])


def collect_evaluation_videos(image_size: int, episodes: int, seed: int = 0, noise: float = 0.1,
                              tasks: tuple[str, ...] = EVALUATION_TASKS
                              ) -> dict[str, list[torch.Tensor]]:
    """Successful expert videos of each evaluation task, rendered at ``image_size``."""
    videos = {}
    for task in tasks:
        collected = collect_expert_episodes(task, seed=seed, num_episodes=episodes, noise=noise,
                                            render=True, image_size=image_size,
                                            max_episode_steps=300)
        videos[task] = [episode_frames(e) for e in collected if e["next", "success"].any()]
    return videos


@torch.no_grad()
def value_order_correlations(encoder: Encoder, videos: dict[str, list[torch.Tensor]],
                             frame_stride: int = 1, batch_size: int = 64
                             ) -> dict[str, dict[str, float]]:
    """Mean Spearman rho per task: ``{"text": {task: rho}, "image": {task: rho}}``.

    ``frame_stride`` > 1 keeps every ``frame_stride``-th frame (always with the last frame), for
    slow encoders.
    """
    results: dict[str, dict[str, float]] = {"text": {}, "image": {}}
    for task, task_videos in videos.items():
        goal_text = encoder.embed_text([TASKS[task].goal_prompt])
        text_rhos, image_rhos = [], []
        for frames in task_videos:
            index = torch.arange(len(frames) - 1, -1, -frame_stride).flip(0)
            embeddings = torch.cat([encoder.embed_images(chunk)
                                    for chunk in frames[index].split(batch_size)])
            text_value = F.cosine_similarity(embeddings, goal_text, dim=-1)
            image_value = F.cosine_similarity(embeddings, embeddings[-1:], dim=-1)
            text_rhos.append(spearmanr(index.numpy(), text_value.numpy()).statistic)
            # The goal frame's similarity to itself is 1 by construction: leave it out.
            image_rhos.append(spearmanr(index[:-1].numpy(), image_value[:-1].numpy()).statistic)
        results["text"][task] = float(np.nanmean(text_rhos))
        results["image"][task] = float(np.nanmean(image_rhos))
    return results


def random_liv_encoder(seed: int = 0) -> Encoder:
    """LIV's architecture (open_clip RN50-quickgelu) with random weights, loaded the LIV way.

    ``save_random_liv_checkpoint`` writes random weights in LIV's on-disk format to a temporary
    file, read back by ``load_encoder("liv", checkpoint=...)``.
    """
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "random_liv.pt"
        save_random_liv_checkpoint(path, seed=seed)
        return load_encoder("liv", checkpoint=str(path))


def evaluate_encoders(encoders: dict[str, Callable[[], Encoder]],
                      small_videos: dict[str, list[torch.Tensor]],
                      large_videos: dict[str, list[torch.Tensor]],
                      large_stride: int) -> list[dict]:
    """One row per encoder: per-task text-goal rho, their mean and the mean image-goal rho.

    Encoders whose name starts with ``"LIV"`` see ``large_videos`` (rendered at 224) every
    ``large_stride``-th frame; the others see ``small_videos`` (rendered at their input size).
    """
    rows = []
    for label, make in encoders.items():
        start = time.perf_counter()
        encoder = make()
        large = label.startswith("LIV")
        result = value_order_correlations(encoder, large_videos if large else small_videos,
                                          frame_stride=large_stride if large else 1)
        row = {"encoder": label}
        row.update({task: result["text"][task] for task in EVALUATION_TASKS})
        row["mean text-goal rho"] = float(np.mean(list(result["text"].values())))
        row["mean image-goal rho"] = float(np.mean(list(result["image"].values())))
        row["seconds"] = time.perf_counter() - start
        rows.append(row)
        print(f"  {label}: text-goal rho {row['mean text-goal rho']:+.3f}, image-goal rho "
              f"{row['mean image-goal rho']:+.3f} ({row['seconds']:.0f} s)", flush=True)
    return rows


def markdown_table(rows: list[dict]) -> str:
    """Rows from :func:`evaluate_encoders` as a markdown table (seconds left out)."""
    keys = [key for key in rows[0] if key != "seconds"]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append("| " + " | ".join(
            f"{row[key]:+.3f}" if isinstance(row[key], float) else str(row[key]) for key in keys
        ) + " |")
    return "\n".join(lines)


def default_encoders(small_checkpoint: str | None, liv_checkpoint: str | None, seed: int,
                     with_random_liv: bool = True) -> dict[str, Callable[[], Encoder]]:
    """The comparison of the model card: shipped small, random small, random LIV, real LIV."""
    def random_small() -> Encoder:
        config = SmallEncoder.from_pretrained(small_checkpoint).config()
        torch.manual_seed(seed)
        return SmallEncoder(**config).freeze()

    encoders: dict[str, Callable[[], Encoder]] = {
        "metaworld_small (trained)": lambda: SmallEncoder.from_pretrained(small_checkpoint),
        "metaworld_small (random weights)": random_small,
    }
    if with_random_liv:
        encoders["LIV RN50 (random weights)"] = lambda: random_liv_encoder(seed)
    if liv_checkpoint:
        encoders["LIV RN50 (released weights)"] = lambda: load_encoder(
            "liv", checkpoint=liv_checkpoint)
    return encoders
