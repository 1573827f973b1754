"""A reward from a config: the one translation of the recipes' ``reward.*`` keys into
:class:`~temporal_torchrl.rewards.TemporalReward`'s arguments, and the one builder that the
training recipe, the offline benchmark (``recipes/evaluate_rewards.py``) and the reports (which
load a run's saved heads) call.

Every reward's hyperparameters, the built-ins' and one's own alike, are its registered options,
set under ``reward.options`` (:func:`~temporal_torchrl.rewards.register_reward`). The keys that
set the built-ins' before (``reward.window``, ``reward.certainty_bandwidth``,
``reward.certainty_prior``: :data:`DEPRECATED_KEYS`) are read for one more release as the option
of the same name (:func:`moved_options`); null, or their old default, means not set.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from torch import Tensor

from temporal_torchrl.defaults import CERTAINTY_BANDWIDTH, CERTAINTY_PRIOR, WINDOW_LENGTH
from temporal_torchrl.rewards.registry import registered, single_part
from temporal_torchrl.rewards.temporal import TemporalReward

#: :class:`~temporal_torchrl.rewards.TemporalReward`'s arguments by the ``reward.*`` key that
#: sets each (besides the parts and the options).
CONFIG_KEYS = {"rho": "rho", "lambda_": "lambda_", "k": "k", "alpha": "alpha",
               "projection": "projection", "certainty_scaling": "certainty_scaling"}
#: The ``reward.*`` keys that set an option of a built-in reward before ``reward.options`` held
#: every reward's (deprecated: read for one more release), each the option of the same name,
#: with the default it had. A saved run's config.json holds all three, at these values unless
#: its run changed one, so a key at its old default means "not set": such runs resume without a
#: warning, with the run directory name they had.
DEPRECATED_KEYS = MappingProxyType({"window": WINDOW_LENGTH,
                                    "certainty_bandwidth": CERTAINTY_BANDWIDTH,
                                    "certainty_prior": CERTAINTY_PRIOR})
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


def deprecated_settings(reward: Mapping[str, Any]) -> dict[str, Any]:
    """The :data:`DEPRECATED_KEYS` a config's ``reward`` section sets, ``{key: value}``: those
    neither null (the schema's "not set") nor at their old default (what every config held
    before)."""
    return {key: reward[key] for key, old_default in DEPRECATED_KEYS.items()
            if reward.get(key) is not None and reward[key] != old_default}


def moved_options(reward: Mapping[str, Any]) -> dict[str, Any]:
    """A config's ``reward.options`` with what its deprecated keys set
    (:func:`deprecated_settings`) moved in: ``reward.window=12`` means
    ``reward.options.window=12``. The recipes' validation stores the result (warning about each
    key moved); the run directory's name and the reward of a run's saved config read it, so a
    config read before validation or saved by an older version means the same.

    Raises:
        ValueError: a key set both ways to different values.
    """
    options = dict(reward.get("options") or {})
    for key, value in deprecated_settings(reward).items():
        if key in options and options[key] != value:
            raise ValueError(
                f"config reward.{key}={value!r} and reward.options.{key}={options[key]!r} "
                f"disagree: reward.{key} is the deprecated spelling of reward.options.{key}. "
                f"Keep reward.options.{key} and remove reward.{key} (from the command line, or "
                "from a resumed run's config.json).")
        options[key] = value
    return options


def with_moved_options(config: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of a whole config (plain containers, as a run's config.json holds it) with its
    ``reward`` section as the recipes' validation leaves it: what the :data:`DEPRECATED_KEYS`
    set moved into ``reward.options`` (:func:`moved_options`), those keys null. Configs that
    mean the same run then compare equal, whichever version wrote them: a run's saved config
    against the command line's, or runs grouped into configurations by the reports.

    Raises:
        ValueError: as :func:`moved_options`.
    """
    if not isinstance(config.get("reward"), Mapping):
        return dict(config)
    reward = {**config["reward"], "options": moved_options(config["reward"])}
    reward.update({key: None for key in DEPRECATED_KEYS if key in reward})
    return {**config, "reward": reward}


def reward_options(config: Mapping[str, Any], *, variant: str | None = None) -> dict[str, Any]:
    """:class:`~temporal_torchrl.rewards.TemporalReward`'s keyword arguments from a config's
    ``reward.*``: its parts, every setting the reward's forward depends on, and ``options``, the
    parts' own (``reward.options``, set with ``+reward.options.<name>=<value>``; absent from
    the configs of runs older than it; the :data:`DEPRECATED_KEYS` moved in,
    :func:`moved_options`).

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
    options = moved_options(reward)
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
