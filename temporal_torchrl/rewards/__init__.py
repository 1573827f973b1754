"""Positional and directional VLM rewards (thesis chapter 4) and their trainable heads."""

from temporal_torchrl.rewards.directional import DIRECTIONAL
from temporal_torchrl.rewards.heads import RewardHeads, heads_input_dims
from temporal_torchrl.rewards.positional import (
    POSITIONAL,
    PROJECTIONS,
    RewardFunction,
    cosine_similarity,
    goal_baseline_regularise,
)
from temporal_torchrl.rewards.temporal import REWARD_KEYS, TemporalReward

__all__ = [
    "DIRECTIONAL",
    "POSITIONAL",
    "PROJECTIONS",
    "REWARD_KEYS",
    "RewardFunction",
    "RewardHeads",
    "TemporalReward",
    "cosine_similarity",
    "goal_baseline_regularise",
    "heads_input_dims",
]
