"""A render-free stand-in encoder: the env's state vector through a fixed random projection.

NOT a vision-language model. ``StateEncoder`` embeds Metaworld's 39-d ``"observation"`` with a
fixed, seeded Gaussian projection ``s = W o`` (``W`` of shape ``[dim, obs_dim]``, entries
``N(0, 1/obs_dim)``; the buffer ``projection`` holds its transpose), and gives each prompt a fixed
pseudo-random vector derived from a stable hash of its text. Prompts therefore carry no meaning: the
rewards it yields do not reflect the task. It exists so the whole pipeline (embedding, history,
reward transforms, replay buffer, reward-finetuning losses) runs without rendering or a
100M-parameter model, for tests and fast experiments on the algorithm's mechanics.

``dim`` defaults to 1024, LIV's embedding size, so configurations, reward heads and stored
buffers keep the shapes they have with LIV; pass a smaller ``dim`` for speed.
"""

from __future__ import annotations

import hashlib

import torch

from temporal_torchrl.encoders.base import Encoder


class StateEncoder(Encoder):
    """Seeded random projection of state vectors, with a fixed random vector per prompt.

    Args:
        dim: embedding size ``D`` (default 1024, as LIV).
        observation_dim: size of the state vector (39 for Metaworld).
        seed: fixes the projection and the prompt vectors.

    Example:
        >>> import torch
        >>> encoder = StateEncoder(dim=8)
        >>> encoder.embed(torch.zeros(2, 39)).shape
        torch.Size([2, 8])
        >>> bool((encoder.embed_text(["open the drawer"])
        ...       == StateEncoder(dim=8).embed_text(["open the drawer"])).all())
        True
    """

    name = "state"
    input_key = "observation"

    def __init__(self, dim: int = 1024, observation_dim: int = 39, seed: int = 0) -> None:
        super().__init__()
        if dim < 1 or observation_dim < 1:
            raise ValueError(
                f"dim and observation_dim must be positive, got dim={dim}, "
                f"observation_dim={observation_dim}"
            )
        self.dim = int(dim)
        self.observation_dim = int(observation_dim)
        self.seed = int(seed)
        generator = torch.Generator().manual_seed(self.seed)
        projection = torch.randn(self.observation_dim, self.dim, generator=generator)
        self.register_buffer("projection", projection / self.observation_dim**0.5)
        self.freeze()

    def embed_observations(self, observations: torch.Tensor) -> torch.Tensor:
        """State vectors ``[N, observation_dim]`` -> float32 ``[N, dim]``."""
        if observations.ndim != 2 or observations.shape[-1] != self.observation_dim:
            raise ValueError(
                f"expected state vectors of shape [N, {self.observation_dim}], got "
                f"{tuple(observations.shape)}; build the encoder with "
                "observation_dim=<your state size> for other envs"
            )
        return observations.to(self.projection.device, torch.float32) @ self.projection

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        vectors = []
        for text in texts:
            # sha256, not hash(): Python salts str hashes per process.
            digest = hashlib.sha256(f"{self.seed}\0{text}".encode()).digest()
            generator = torch.Generator().manual_seed(int.from_bytes(digest[:8], "little"))
            vectors.append(torch.randn(self.dim, generator=generator))
        return torch.stack(vectors)

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, observation_dim={self.observation_dim}, seed={self.seed}"
