"""A tiny deterministic TorchRL env that emits "embedding" and "success" (rewards tests only).

Each batch element runs episodes of its own fixed length (different lengths give partial resets
in a batched rollout). The embedding encodes where it came from: channel 0 the batch element,
channel 1 the episode number, channel 2 the step t; the other channels are smooth functions of
those, so every embedding is distinct.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Composite, Unbounded
from torchrl.envs import EnvBase


def mock_embedding(element: int, episode: int, step: int, dim: int) -> torch.Tensor:
    """The embedding the mock env emits for (element, episode, step)."""
    tail = [math.sin(0.7 * (j + 1) * step + episode + 0.3 * element) + 0.1 * j
            for j in range(dim - 3)]
    return torch.tensor([element, episode, step, *tail], dtype=torch.float32)


class EmbeddingMockEnv(EnvBase):
    """Episodes of ``episode_lengths[i]`` steps; success from step ``success_from`` on."""

    def __init__(self, embedding_dim: int = 6, episode_lengths: tuple[int, ...] = (7,),
                 success_from: int = 4):
        batch = torch.Size([len(episode_lengths)]) if len(episode_lengths) > 1 else torch.Size([])
        super().__init__(batch_size=batch)
        self.embedding_dim = embedding_dim
        self.success_from = success_from
        self.lengths = torch.tensor(episode_lengths).reshape(batch)
        self.elements = torch.arange(len(episode_lengths)).reshape(batch)
        self.steps = torch.zeros(batch, dtype=torch.long)
        self.episodes = torch.full(batch, -1, dtype=torch.long)
        flag = Binary(n=1, shape=(*batch, 1), dtype=torch.bool)
        self.observation_spec = Composite(
            embedding=Unbounded((*batch, embedding_dim)), success=flag.clone(), shape=batch)
        self.action_spec = Bounded(-1.0, 1.0, shape=(*batch, 1))
        self.reward_spec = Unbounded((*batch, 1))
        self.full_done_spec = Composite(done=flag.clone(), terminated=flag.clone(),
                                        truncated=flag.clone(), shape=batch)

    def _observe(self) -> TensorDict:
        embedding = torch.stack([
            mock_embedding(int(e), int(ep), int(t), self.embedding_dim)
            for e, ep, t in zip(self.elements.reshape(-1), self.episodes.reshape(-1),
                                self.steps.reshape(-1), strict=True)
        ]).reshape(*self.batch_size, self.embedding_dim)
        success = (self.steps >= self.success_from).unsqueeze(-1)
        truncated = (self.steps >= self.lengths).unsqueeze(-1)
        return TensorDict({"embedding": embedding, "success": success, "done": truncated.clone(),
                           "terminated": torch.zeros_like(truncated), "truncated": truncated},
                          self.batch_size)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDict:
        reset = None if tensordict is None else tensordict.get("_reset", None)
        mask = (torch.ones(self.batch_size, dtype=torch.bool) if reset is None
                else reset.reshape(self.batch_size))
        self.steps = torch.where(mask, 0, self.steps)
        self.episodes = torch.where(mask, self.episodes + 1, self.episodes)
        return self._observe()

    def _step(self, tensordict: TensorDictBase) -> TensorDict:
        self.steps = self.steps + 1
        out = self._observe()
        out.set("reward", out["success"].float() - 1.0)
        return out

    def _set_seed(self, seed: int | None) -> None:
        return None
