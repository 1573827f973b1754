"""A run's reward from its config: the one translation of ``reward.*`` into
:class:`~temporal_torchrl.rewards.TemporalReward`'s arguments, used by the recipe that trains it
and by the reports that load its saved heads."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torch import Tensor

from temporal_torchrl.rewards import TemporalReward


def none_or_name(value: Any) -> str | None:
    """A reward name from the config, None for null or "none"."""
    return None if value is None or str(value).lower() == "none" else str(value)


def has_vlm_reward(positional: Any, directional: Any) -> bool:
    """Whether a reward with these parts (config values) is a VLM reward at all."""
    return none_or_name(positional) is not None or none_or_name(directional) is not None


def uses_vlm_reward(config: Mapping[str, Any]) -> bool:
    """Whether the run's config has a VLM reward (a positional or a directional part)."""
    return has_vlm_reward(config["reward"]["positional"], config["reward"]["directional"])


def reward_options(config: Mapping[str, Any]) -> dict[str, Any]:
    """:class:`~temporal_torchrl.rewards.TemporalReward`'s keyword arguments from a run's
    config (the recipe's ``reward.*``), every setting the reward's forward depends on."""
    reward = config["reward"]
    return {"positional": none_or_name(reward["positional"]),
            "directional": none_or_name(reward["directional"]),
            "rho": reward["rho"], "lambda_": reward["lambda_"], "k": reward["k"],
            "alpha": reward["alpha"], "projection": reward["projection"],
            "window_length": reward["window"],
            "certainty_bandwidth": reward["certainty_bandwidth"],
            "certainty_prior": reward["certainty_prior"],
            "certainty_scaling": reward["certainty_scaling"]}


def reward_from_config(config: Mapping[str, Any], goal_embedding: Tensor,
                       baseline_embedding: Tensor) -> TemporalReward:
    """The run's :class:`~temporal_torchrl.rewards.TemporalReward` with the given goal and
    baseline text embeddings (fresh heads: load a checkpoint's ``"reward"`` state into it)."""
    return TemporalReward(goal_embedding.shape[-1], goal_embedding, baseline_embedding,
                          **reward_options(config))
