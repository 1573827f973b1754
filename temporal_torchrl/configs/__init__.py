"""The recipes' config schemas, as Hydra structured configs, and the rules they cannot state.

- :mod:`.recipe`: ``recipes/sac_temporal.py``'s (``recipes/config.yaml``);
- :mod:`.reward_quality`: ``recipes/evaluate_rewards.py``'s (``recipes/evaluate_rewards.yaml``);
- :mod:`.fields`: a key's simple range, declared next to its type;
- :mod:`.rules`: the checks that relate keys or need code, for both, and what the recipes make
  of a few values (devices, ``reward.modules``).

Importing this package stores the schemas in Hydra's ConfigStore (:func:`register_configs`),
under the names the YAML files' defaults lists use, so that ``hydra.main`` and ``hydra.compose``
find them. It also registers the OmegaConf resolver ``ras_budget`` (:func:`ras_budget`), so
that a config can run each task to its own budget: ``train.episodes: ${ras_budget:${env.task}}``.
"""

from hydra.core.config_store import ConfigStore
from omegaconf import OmegaConf

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


def ras_budget(task: str) -> int:
    """The episode budget e of RAS(e; w) for ``task`` (thesis Table 5.1), for the resolver of
    the same name; a ``ValueError`` for a task the thesis does not evaluate."""
    from temporal_torchrl.envs import get_task  # the envs import torch and Metaworld: on use only

    budget = get_task(task).ras_budget
    if budget is None:
        raise ValueError(f"${{ras_budget:{task}}}: task {task!r} has no RAS budget (the thesis "
                         "evaluates six tasks: thesis Table 5.1). Give train.episodes a number "
                         "for it instead.")
    return budget


register_configs()
OmegaConf.register_new_resolver("ras_budget", ras_budget, replace=True)

__all__ = [
    "RECIPE_SCHEMA",
    "REWARD_QUALITY_SCHEMA",
    "RecipeConfig",
    "RewardQualityConfig",
    "ras_budget",
    "register_configs",
]
