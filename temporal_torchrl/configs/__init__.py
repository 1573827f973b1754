"""The recipes' config schemas, as Hydra structured configs, and the rules they cannot state.

- :mod:`.recipe`: ``recipes/sac_temporal.py``'s (``recipes/config.yaml``);
- :mod:`.reward_quality`: ``recipes/evaluate_rewards.py``'s (``recipes/evaluate_rewards.yaml``);
- :mod:`.fields`: a key's simple range, declared next to its type;
- :mod:`.rules`: the checks that relate keys or need code, for both, and what the recipes make
  of a few values (devices, ``reward.modules``).

Importing this package stores the schemas in Hydra's ConfigStore (:func:`register_configs`),
under the names the YAML files' defaults lists use, so that ``hydra.main`` and ``hydra.compose``
find them.
"""

from hydra.core.config_store import ConfigStore

from temporal_torchrl.configs.recipe import RecipeConfig
from temporal_torchrl.configs.reward_quality import RewardQualityConfig

#: ``recipes/config.yaml``'s schema, as its defaults list names it.
RECIPE_SCHEMA = "recipe_schema"
#: ``recipes/evaluate_rewards.yaml``'s schema, as its defaults list names it.
REWARD_QUALITY_SCHEMA = "reward_quality_schema"


def register_configs() -> None:
    """Store both schemas in Hydra's ConfigStore (again: the same nodes replace themselves)."""
    store = ConfigStore.instance()
    store.store(name=RECIPE_SCHEMA, node=RecipeConfig)
    store.store(name=REWARD_QUALITY_SCHEMA, node=RewardQualityConfig)


register_configs()

__all__ = [
    "RECIPE_SCHEMA",
    "REWARD_QUALITY_SCHEMA",
    "RecipeConfig",
    "RewardQualityConfig",
    "register_configs",
]
