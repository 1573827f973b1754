"""A run's reward from its config, by the names the runs package gives the reward's config
reading: the translation of ``reward.*`` and the builder are
:mod:`temporal_torchrl.rewards.config`'s, used by the recipe that trains a run, the offline
benchmark, and the reports that load a run's saved heads."""

from temporal_torchrl.rewards.config import (
    has_vlm_reward,
    none_or_name,
    reward_from_config,
    reward_options,
    uses_vlm_reward,
)

__all__ = ["has_vlm_reward", "none_or_name", "reward_from_config", "reward_options",
           "uses_vlm_reward"]
