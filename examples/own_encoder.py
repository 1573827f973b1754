"""Your own encoder: a frozen Encoder subclass, used wherever the package takes an encoder.

    python examples/own_encoder.py

The encoder here is a toy (a fixed random projection of the state vector, a bag of hashed words
for prompts: no vision, no language understanding); a real one would wrap a model. Anything
with the Encoder interface (``dim``, ``input_key``, ``embed_images`` or ``embed_observations``,
``_encode_text``) goes into make_temporal_reward, make_temporal_env, the replay buffer and the
reward-quality benchmark's functions.
"""

from __future__ import annotations

import argparse
import hashlib

import torch

from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs import make_temporal_env, make_temporal_reward


# [encoder]
class BagOfWordsStateEncoder(Encoder):
    """Observations through a fixed random projection; a prompt is the mean of one fixed random
    vector per word."""

    name = "bag_of_words_state"
    input_key = "observation"  # "pixels" for an image encoder (then implement embed_images)

    def __init__(self, dim: int = 64, observation_dim: int = 39, seed: int = 0) -> None:
        super().__init__()
        self.dim, self.seed = dim, seed
        generator = torch.Generator().manual_seed(seed)
        projection = torch.randn(observation_dim, dim, generator=generator)
        self.register_buffer("projection", projection / observation_dim**0.5)
        self.freeze()  # eval mode, no gradients: encoders are frozen

    def embed_observations(self, observations: torch.Tensor) -> torch.Tensor:
        return observations.to(self.projection.device, torch.float32) @ self.projection

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        return torch.stack([torch.stack([self._word(word) for word in text.lower().split()])
                            .mean(0) for text in texts])

    def _word(self, word: str) -> torch.Tensor:
        digest = hashlib.sha256(f"{self.seed}\0{word}".encode()).digest()
        generator = torch.Generator().manual_seed(int.from_bytes(digest[:8], "little"))
        return torch.randn(self.dim, generator=generator)
# [/encoder]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="a toy encoder in the temporal env")
    parser.add_argument("--task", default="drawer-open")
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args(argv)

    # [use]
    encoder = BagOfWordsStateEncoder(dim=64)
    reward = make_temporal_reward(args.task, encoder, positional="furl", directional="d3",
                                  rho=1.0, lambda_=4.0)
    env = make_temporal_env(args.task, seed=0, encoder=encoder, reward=reward)
    rollout = env.rollout(args.steps)
    # [/use]
    print(f"{encoder.name}: embedding {tuple(rollout['embedding'].shape)}, "
          f"vlm_reward {rollout['next', 'vlm_reward'].mean():+.3f} on average")


if __name__ == "__main__":
    main()
