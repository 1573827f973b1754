"""One task of the offline benchmark from its config: the dataset it collects (or loads from the
cache), split by episode, and what every scorer reads from it.

``recipes/evaluate_rewards.py`` scores every variant with these; the studies under
``docs/results/beyond_thesis/`` compose the same config and read the same data.
"""

from __future__ import annotations

import dataclasses

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict

from temporal_torchrl.data import goal_image_embedding
from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs.task_reward import task_text_embeddings
from temporal_torchrl.params import DatasetParams, EnvParams
from temporal_torchrl.reward_quality.dataset import (
    DatasetSpec,
    RewardDataset,
    load_or_collect,
    split_by_episode,
)


def task_config(cfg: DictConfig, task: str) -> DictConfig:
    """``cfg`` (the benchmark's config, ``env.task`` one task or a list) with ``env.task`` set to
    one task."""
    single = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True))
    single.env.task = task
    return single


def dataset_spec(cfg: DictConfig) -> DatasetSpec:
    """The :class:`~temporal_torchrl.reward_quality.DatasetSpec` of a one-task config's
    ``env.*`` and ``dataset.*``."""
    return DatasetSpec.of(EnvParams.from_section(cfg.env),
                          DatasetParams.from_section(cfg.dataset))


@dataclasses.dataclass(frozen=True)
class TaskData:
    """One task's dataset split by episode, and what every scorer reads from it."""

    dataset: RewardDataset
    train: RewardDataset
    held_out: RewardDataset
    successful: list[TensorDict]  # held-out successful episodes
    failed: list[TensorDict]  # held-out failed episodes
    goal_image: torch.Tensor  # s_g, from the first training expert
    goal_embedding: torch.Tensor
    baseline_embedding: torch.Tensor


def prepare_task(cfg: DictConfig, encoder: Encoder) -> TaskData:
    """Collect (or load from the cache) a one-task config's dataset and split it by episode;
    s_g comes from the first training expert, as the training recipe takes it from its first
    expert."""
    encoder_options = OmegaConf.to_container(cfg.encoder.options, resolve=True) or {}
    dataset = load_or_collect(dataset_spec(cfg), encoder, cfg.dataset.cache_dir,
                              encoder_description={"options": encoder_options})
    train_indices, held_out_indices = split_by_episode(
        dataset.kinds, cfg.dataset.held_out_fraction, cfg.env.seed)
    train, held_out = dataset.subset(train_indices), dataset.subset(held_out_indices)
    outcomes = list(zip(held_out.episodes, held_out.successful, strict=True))
    goal_image = goal_image_embedding(next(
        episode for episode, ok in zip(train.episodes, train.successful, strict=True) if ok))
    goal, baseline = task_text_embeddings(cfg.env.task, encoder, cfg.reward.baseline)
    return TaskData(dataset, train, held_out,
                    successful=[episode for episode, ok in outcomes if ok],
                    failed=[episode for episode, ok in outcomes if not ok],
                    goal_image=goal_image, goal_embedding=goal, baseline_embedding=baseline)
