"""Positional and directional VLM rewards (thesis chapter 4) and their trainable heads.

Add a reward of your own with :func:`register_reward`.
"""

from temporal_torchrl.rewards.certainty import (
    CertaintyMemory,
    direction_certainty,
    reference_scales,
)
from temporal_torchrl.rewards.directional import DIRECTIONAL, straight_window, window_tokens
from temporal_torchrl.rewards.heads import RewardHeads, SequenceEncoder, heads_input_dims
from temporal_torchrl.rewards.positional import (
    POSITIONAL,
    PROJECTIONS,
    cosine_similarity,
    goal_baseline_regularise,
)
from temporal_torchrl.rewards.registry import (
    IMAGE_INPUTS,
    OBJECTIVES,
    RewardFunction,
    objective_of,
    register_reward,
    unregister_reward,
)
from temporal_torchrl.rewards.temporal import REWARD_KEYS, TemporalReward

__all__ = [
    "DIRECTIONAL",
    "IMAGE_INPUTS",
    "OBJECTIVES",
    "POSITIONAL",
    "PROJECTIONS",
    "REWARD_KEYS",
    "CertaintyMemory",
    "RewardFunction",
    "RewardHeads",
    "SequenceEncoder",
    "TemporalReward",
    "cosine_similarity",
    "direction_certainty",
    "goal_baseline_regularise",
    "heads_input_dims",
    "objective_of",
    "reference_scales",
    "register_reward",
    "straight_window",
    "unregister_reward",
    "window_tokens",
]
