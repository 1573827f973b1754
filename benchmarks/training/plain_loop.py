"""Section ``plain_loop`` (``reference``): the recipe's own overhead.

The recipe without a VLM reward against a plain TorchRL SAC loop on the same env
(``TensorDictReplayBuffer``, TorchRL's ``SACLoss``, the same networks and schedule).
"""

from __future__ import annotations

import time
from pathlib import Path

import sac_temporal
import torch
from omegaconf import DictConfig
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.envs import make_env
from temporal_torchrl.training import factories
from training.common import Budget, recipe_config
from training.sac_update import torchrl_sac_update


def plain_sac_steps_per_second(cfg: DictConfig, episodes: int) -> float:
    """The reference: TorchRL env.step + per-step buffer extend + SACLoss update, no VLM."""
    env = make_env(cfg.env.task, cfg.env.seed, max_episode_steps=cfg.env.max_episode_steps)
    actor, _ = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    update = torchrl_sac_update(cfg, actor)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(episodes * 1000),
                                    batch_size=cfg.sac.batch_size)
    steps = 0
    start = time.perf_counter()
    for _ in range(episodes):
        tensordict = env.reset()
        for _ in range(cfg.env.max_episode_steps):
            with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
                actor(tensordict)
            tensordict = env.step(tensordict)
            buffer.add(tensordict.select("observation", "action", "next"))
            steps += 1
            if steps > cfg.env.max_episode_steps:  # the recipe updates from its 2nd episode on
                update(buffer.sample())
            if tensordict["next", "done"].item():
                break
            tensordict = step_mdp(tensordict)
    return steps / (time.perf_counter() - start)


def reference_rows(tmp: Path, budget: Budget) -> list[dict]:
    """The recipe's env steps/s without a VLM reward over ``budget.plain_loop_episodes``
    episodes, against :func:`plain_sac_steps_per_second` over as many."""
    episodes = budget.plain_loop_episodes
    cfg = recipe_config(tmp / "sac", budget, f"train.episodes={episodes}",
                        f"env.max_episode_steps={budget.plain_loop_length}",
                        "reward.positional=none", "reward.directional=none")
    summary = sac_temporal.train(cfg)
    reference = plain_sac_steps_per_second(cfg, episodes)
    return [{"measure": "whole loop, no VLM reward (env steps/s)",
             "project": summary["steps_per_second"], "reference": reference,
             "reference is": "plain TorchRL SAC loop",
             "ratio": summary["steps_per_second"] / reference}]
