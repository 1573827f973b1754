"""Training episodes from a collector's vector steps: one episode per env, assembled step by step.

A collector with ``env.num_envs`` envs yields one vector step per iteration; each env's episode
ends on its own step. :class:`EpisodeAssembler` keeps each env's steps (the keys the replay and
the episode rows need, never pixels) and hands over an env's whole trajectory when it ends,
with the stage its episode ran in; :func:`episode_row` is its line in ``episodes.csv``.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase

from temporal_torchrl.protocol_metrics import episode_success

#: What an episode keeps from each step (pixels never reach the buffer).
STEP_KEYS = ("observation", "embedding", "action", "success", ("next", "observation"),
             ("next", "embedding"), ("next", "success"), ("next", "terminated"),
             ("next", "task_reward"), ("next", "vlm_reward"))


class EpisodeAssembler:
    """Each env's episode in progress (see the module doc).

    Args:
        num_envs: envs stepped together.
        stage: the finetuning stage (1 or 2) the first episodes run in.
    """

    def __init__(self, num_envs: int, stage: int) -> None:
        self.num_envs = num_envs
        self._steps: list[list[TensorDictBase]] = [[] for _ in range(num_envs)]
        self._stages = [stage] * num_envs

    def add(self, data: TensorDictBase) -> list[int]:
        """Add one vector step; returns the envs whose episode it ended, in env order."""
        data = data.reshape(self.num_envs)
        for index in range(self.num_envs):
            self._steps[index].append(data[index].select(*STEP_KEYS, strict=False))
        return data["next", "done"].reshape(self.num_envs).nonzero().reshape(-1).tolist()

    def pop(self, index: int) -> tuple[TensorDictBase, int]:
        """Env ``index``'s ended episode ``[T]`` and the stage it ran in."""
        trajectory, self._steps[index] = torch.stack(self._steps[index]), []
        return trajectory, self._stages[index]

    def begin(self, index: int, stage: int) -> None:
        """Env ``index``'s next episode runs in ``stage`` (decided once the last is stored)."""
        self._stages[index] = stage


def episode_row(trajectory: TensorDictBase, episode: int, env_steps: int,
                stage: int) -> dict[str, Any]:
    """An ended episode's ``episodes.csv`` row: its success, its return (the sum of the sparse
    task rewards ``success - 1``), its mean VLM reward (0 without one) and its stage."""
    task_rewards = trajectory.get(("next", "task_reward"),
                                  trajectory["next", "success"].float() - 1.0)
    vlm_rewards = trajectory.get(("next", "vlm_reward"), torch.zeros_like(task_rewards))
    return {"episode": episode, "env_steps": env_steps,
            "success": int(episode_success(trajectory["next", "success"])),
            "return": float(task_rewards.sum()), "mean_vlm_reward": float(vlm_rewards.mean()),
            "stage": stage}
