"""Episode replay on TorchRL's buffer API (writer, samplers, layouts), labels and experts."""

from temporal_torchrl.data.buffer import EpisodeReplayBuffer
from temporal_torchrl.data.episodes import (
    NEGATIVE,
    POSITIVE,
    UNLABELLED,
    episode_labels,
    episode_rows,
)
from temporal_torchrl.data.experts import (
    embed_episode,
    goal_image_embedding,
    goal_image_from_rows,
)
from temporal_torchrl.data.history import episode_history, state_index, transition_index
from temporal_torchrl.data.layouts import FinetuningLayout, TransitionLayout
from temporal_torchrl.data.samplers import FINETUNING_GROUPS, FinetuningSampler, TransitionSampler
from temporal_torchrl.data.storage import EpisodeStorage
from temporal_torchrl.data.writer import EpisodeWriter

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
    "episode_history",
    "episode_labels",
    "episode_rows",
    "goal_image_embedding",
    "goal_image_from_rows",
    "state_index",
    "transition_index",
]
