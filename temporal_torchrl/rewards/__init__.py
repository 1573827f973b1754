"""Positional and directional VLM rewards (thesis chapter 4) and their trainable heads.

Add a reward of your own with :func:`register_reward`; build the reward a config describes with
:func:`reward_from_config`. Every default is written once, in :mod:`temporal_torchrl.defaults`.
"""

from temporal_torchrl.rewards.certainty import (
    CertaintyMemory,
    direction_certainty,
    reference_scales,
)
from temporal_torchrl.rewards.config import reward_from_config, reward_options
from temporal_torchrl.rewards.directional import straight_window, window_tokens
from temporal_torchrl.rewards.heads import RewardHeads, SequenceEncoder, heads_input_dims
from temporal_torchrl.rewards.positional import (
    PROJECTIONS,
    cosine_similarity,
    goal_baseline_regularise,
)
from temporal_torchrl.rewards.registry import (
    DIRECTIONAL,
    IMAGE_INPUTS,
    OBJECTIVES,
    POSITIONAL,
    REWARDS,
    RegisteredReward,
    RewardFunction,
    objective_of,
    register_reward,
    single_part,
    unregister_reward,
)
from temporal_torchrl.rewards.temporal import REWARD_KEYS, TemporalReward

__all__ = [
    "DIRECTIONAL",
    "IMAGE_INPUTS",
    "OBJECTIVES",
    "POSITIONAL",
    "PROJECTIONS",
    "REWARDS",
    "REWARD_KEYS",
    "CertaintyMemory",
    "RegisteredReward",
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
    "reward_from_config",
    "reward_options",
    "single_part",
    "straight_window",
    "unregister_reward",
    "window_tokens",
]
