"""A reward from a config: the one translation of the recipes' ``reward.*`` keys into
:class:`~temporal_torchrl.rewards.TemporalReward`'s arguments, and the one builder that the
training recipe, the offline benchmark (``recipes/evaluate_rewards.py``) and the reports (which
load a run's saved heads) call."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torch import Tensor

from temporal_torchrl.rewards.registry import registered, single_part
from temporal_torchrl.rewards.temporal import TemporalReward

#: :class:`~temporal_torchrl.rewards.TemporalReward`'s arguments by the ``reward.*`` key that
#: sets each (besides the parts).
CONFIG_KEYS = {"rho": "rho", "lambda_": "lambda_", "k": "k", "alpha": "alpha",
               "projection": "projection", "window": "window_length",
               "certainty_bandwidth": "certainty_bandwidth",
               "certainty_prior": "certainty_prior", "certainty_scaling": "certainty_scaling"}
#: The keys that shape only the reward the agent receives (the total r_task + rho (r_P +
#: lambda r_D) and the certainty factor of ``certainty_scaling``), not the values of a part: a
#: variant scored alone reads none of them (``recipes/evaluate_rewards.yaml`` has none).
AGENT_KEYS = ("rho", "lambda_", "certainty_scaling")


def none_or_name(value: Any) -> str | None:
    """A reward name from the config, None for null or "none"."""
    return None if value is None or str(value).lower() == "none" else str(value)


def has_vlm_reward(positional: Any, directional: Any) -> bool:
    """Whether a reward with these parts (config values) is a VLM reward at all."""
    return none_or_name(positional) is not None or none_or_name(directional) is not None


def uses_vlm_reward(config: Mapping[str, Any]) -> bool:
    """Whether the run's config has a VLM reward (a positional or a directional part)."""
    return has_vlm_reward(config["reward"]["positional"], config["reward"]["directional"])


def reward_options(config: Mapping[str, Any], *, variant: str | None = None) -> dict[str, Any]:
    """:class:`~temporal_torchrl.rewards.TemporalReward`'s keyword arguments from a config's
    ``reward.*``: its parts, every setting the reward's forward depends on, and ``options``, the
    parts' own (``reward.options``, set with ``+reward.options.<name>=<value>``; absent from
    the configs of runs older than it).

    Args:
        config: a config with a ``reward`` section (a run's, or the offline benchmark's).
        variant: None: the parts are the config's ``reward.positional`` and
            ``reward.directional``. A registered reward's name: it is the only part, in the slot
            of its kind, the :data:`AGENT_KEYS` are not read (the offline benchmark scores
            its listed variants one at a time), and of ``reward.options`` only the variant's
            own.
    """
    reward = config["reward"]
    if variant is None:
        parts = {"positional": none_or_name(reward["positional"]),
                 "directional": none_or_name(reward["directional"])}
    else:
        parts = single_part(variant)
    options = dict(reward.get("options") or {})
    if variant is not None:
        options = {key: value for key, value in options.items()
                   if key in registered(variant).options}
    return {**parts, **{argument: reward[key] for key, argument in CONFIG_KEYS.items()
                        if variant is None or key not in AGENT_KEYS}, "options": options}


def reward_from_config(config: Mapping[str, Any], goal_embedding: Tensor,
                       baseline_embedding: Tensor, *, variant: str | None = None
                       ) -> TemporalReward:
    """The :class:`~temporal_torchrl.rewards.TemporalReward` of a config's ``reward.*`` (see
    :func:`reward_options`, ``variant`` included) with the given goal and baseline text
    embeddings ``[D]``; its heads are freshly initialised (seed torch first for reproducible
    heads; load a checkpoint's ``"reward"`` state into them to restore a run's)."""
    return TemporalReward(goal_embedding.shape[-1], goal_embedding, baseline_embedding,
                          **reward_options(config, variant=variant))
