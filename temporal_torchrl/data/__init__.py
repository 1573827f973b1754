"""Episode replay on TorchRL's buffer API (writer, samplers, layouts), labels and experts."""

from temporal_torchrl.data.experts import (
    embed_episode,
    goal_image_embedding,
    goal_image_from_rows,
)
from temporal_torchrl.data.replay import (
    FINETUNING_GROUPS,
    NEGATIVE,
    POSITIVE,
    UNLABELLED,
    EpisodeReplayBuffer,
    EpisodeStorage,
    EpisodeWriter,
    FinetuningLayout,
    FinetuningSampler,
    TransitionLayout,
    TransitionSampler,
    episode_labels,
    episode_rows,
    state_index,
    transition_index,
)

__all__ = [
    "FINETUNING_GROUPS",
    "NEGATIVE",
    "POSITIVE",
    "UNLABELLED",
    "EpisodeReplayBuffer",
    "EpisodeStorage",
    "EpisodeWriter",
    "FinetuningLayout",
    "FinetuningSampler",
    "TransitionLayout",
    "TransitionSampler",
    "embed_episode",
    "episode_labels",
    "episode_rows",
    "goal_image_embedding",
    "goal_image_from_rows",
    "state_index",
    "transition_index",
]
