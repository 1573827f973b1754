"""Episode replay buffer (whole episodes, compact embeddings), labelling and expert preloading."""

from temporal_torchrl.data.experts import embed_episode, goal_image_embedding, preload_experts
from temporal_torchrl.data.replay import (
    NEGATIVE,
    POSITIVE,
    UNLABELLED,
    EpisodeReplayBuffer,
    episode_labels,
)

__all__ = [
    "NEGATIVE",
    "POSITIVE",
    "UNLABELLED",
    "EpisodeReplayBuffer",
    "embed_episode",
    "episode_labels",
    "goal_image_embedding",
    "preload_experts",
]
