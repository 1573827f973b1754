"""Positional and directional VLM rewards (thesis chapter 4) and their trainable heads.

Add a reward of your own with :func:`register_reward`.
"""

from temporal_torchrl.rewards.directional import DIRECTIONAL
from temporal_torchrl.rewards.heads import RewardHeads, heads_input_dims
from temporal_torchrl.rewards.positional import (
    POSITIONAL,
    PROJECTIONS,
    cosine_similarity,
    goal_baseline_regularise,
)
from temporal_torchrl.rewards.registry import (
    IMAGE_INPUTS,
    RewardFunction,
    register_reward,
    unregister_reward,
)
from temporal_torchrl.rewards.temporal import REWARD_KEYS, TemporalReward

__all__ = [
    "DIRECTIONAL",
    "IMAGE_INPUTS",
    "POSITIONAL",
    "PROJECTIONS",
    "REWARD_KEYS",
    "RewardFunction",
    "RewardHeads",
    "TemporalReward",
    "cosine_similarity",
    "goal_baseline_regularise",
    "heads_input_dims",
    "register_reward",
    "unregister_reward",
]
