"""What the schemas cannot state, for both recipes: each key's declared range, the rules that
relate keys or need code (known tasks, registered rewards, existing devices, a task's baseline
text...), and what the recipes make of a few values (devices, ``reward.modules``, the
reward-quality recipe's lists).

:func:`validate_recipe_config` and :func:`validate_reward_quality_config` stop a run before any
work on a bad value with a ``ValueError`` that names the key, says what was expected and how to
fix it. A value of the wrong type never gets this far when Hydra composes the config (it names
the key itself); a resumed config or one built in code gets its types here.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import importlib.util
import re
import sys
import types
import typing
import warnings
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from temporal_torchrl import defaults
from temporal_torchrl.configs.recipe import RecipeConfig
from temporal_torchrl.configs.reward_quality import RewardQualityConfig
from temporal_torchrl.encoders import ENCODERS
from temporal_torchrl.envs import TASKS, baseline_text
from temporal_torchrl.fields import CONSTRAINT
from temporal_torchrl.rewards import DIRECTIONAL, POSITIONAL
from temporal_torchrl.rewards.config import (
    DEPRECATED_KEYS,
    deprecated_settings,
    moved_options,
    none_or_name,
)
from temporal_torchrl.rewards.registry import declared_options, option_expected, option_value

_NOUNS = {int: ("an integer", "integers"), float: ("a number", "numbers"),
          str: ("a string", "strings")}


def _invalid(key: str, value: Any, expected: str) -> ValueError:
    """The error for a bad value: the key, the value, what was expected, how to fix it."""
    return ValueError(f"config {key}={value!r} is invalid: expected {expected}. "
                      f"Fix it on the command line, e.g. {key}=<value>.")


# --------------------------------------------------------------------------- both recipes
#: The groups open by design: the chosen reward's or encoder's options, which the registries
#: check against what that reward or encoder declares (``+reward.options.<key>``).
OPEN_GROUPS = ("reward.options", "encoder.options")
#: Top-level keys a schema does not declare and nothing here reads: Hydra's own settings.
_HYDRA_KEYS = ("hydra",)


def check_declared_keys(cfg: Mapping[str, Any], schema: type, source: str | None = None,
                        prefix: str = "") -> None:
    """Refuse a key ``schema`` does not declare (nothing would read it), outside
    :data:`OPEN_GROUPS` and Hydra's ``hydra.*``: a ``ValueError`` naming the key and its section,
    the nearest declared key when one is close, and where ``+`` applies. ``source``: where the
    config came from, when not the composed command line, preset, protocol and study (a resumed
    run's saved file)."""
    declared = {spec.name: spec for spec in dataclasses.fields(schema)}
    hints = typing.get_type_hints(schema)
    for key in cfg:
        full_key = prefix + str(key)
        if not prefix and key in _HYDRA_KEYS or full_key in OPEN_GROUPS:
            continue
        if key not in declared:
            raise _undeclared(full_key, schema, list(declared), source)
        value, annotation = cfg[key] if isinstance(cfg, Mapping) else None, hints[key]
        if dataclasses.is_dataclass(annotation) and isinstance(value, Mapping):
            check_declared_keys(value, annotation, source, f"{full_key}.")


def _undeclared(full_key: str, schema: type, declared: list[str],
                source: str | None) -> ValueError:
    section, _, name = full_key.rpartition(".")
    where = f"in section {section!r} ({schema.__name__})" if section else \
        f"at the top level ({schema.__name__})"
    close = difflib.get_close_matches(name, declared, n=1, cutoff=0.6)
    suggestion = f" Did you mean {'.'.join(filter(None, (section, close[0])))}?" if close else ""
    found = f" {source} holds it." if source else ""
    return ValueError(
        f"config key {full_key!r} is not declared {where}, so nothing would read it.{found}"
        f"{suggestion} Set a declared key without '+' (declared here: {', '.join(declared)}); "
        f"'+' adds keys only under {' and '.join(OPEN_GROUPS)}, whose keys the chosen reward "
        f"or encoder declares. The schema: {schema.__module__}.")


def typed(cfg: DictConfig, schema: type) -> DictConfig:
    """``cfg`` as ``schema`` types it (a copy). Hydra typed a config it composed already; a
    resumed config (its saved ``config.json`` over the current one) or one built in code gets
    its types, and its type errors, here."""
    try:
        return OmegaConf.merge(OmegaConf.structured(schema), cfg)
    except OmegaConfBaseException as error:
        key = f" {error.full_key}" if error.full_key else ""
        raise ValueError(f"config{key} is invalid: {str(error).splitlines()[0]}. Give it a "
                         f"value of the type {schema.__module__}.{schema.__name__} declares (on "
                         "the command line, or in a resumed run's config.json).") from error


def check_constraints(cfg: DictConfig, schema: type, prefix: str = "") -> None:
    """Every key's range or choices, as ``schema``'s
    :func:`~temporal_torchrl.fields.constrained` fields declare them (for a list, each
    item's); groups are checked key by key."""
    hints = typing.get_type_hints(schema)
    for spec in dataclasses.fields(schema):
        key, value, annotation = prefix + spec.name, cfg[spec.name], hints[spec.name]
        if dataclasses.is_dataclass(annotation):
            check_constraints(value, annotation, f"{key}.")
            continue
        constraint = spec.metadata.get(CONSTRAINT)
        if constraint is None or value is None:  # None gets here only where the type allows it
            continue
        items = list(value) if isinstance(value, ListConfig) else [value]
        if (constraint.nonempty and not items) or not all(map(constraint.admits, items)):
            raise _invalid(key, value, _expected(spec, annotation))


def _expected(spec: dataclasses.Field, annotation: Any) -> str:
    """What a constrained key takes, in words: ``an integer >= 1, or null``, ``a non-empty list
    of integers >= 1, e.g. [256,256]``, ``one of csv, wandb``."""
    constraint = spec.metadata[CONSTRAINT]
    kind, nullable = _without_none(annotation)
    if typing.get_origin(kind) is list:
        items = constraint.describe(_NOUNS[typing.get_args(kind)[0]][1])
        example = ",".join(str(item) for item in spec.default_factory())
        expected = (f"a {'non-empty ' if constraint.nonempty else ''}list of {items}, "
                    f"e.g. [{example}]")
    else:
        expected = constraint.describe(_NOUNS[kind][0])
    return expected + (", or null" if nullable else "")


def _without_none(annotation: Any) -> tuple[Any, bool]:
    """``int | None`` -> ``(int, True)``; ``int`` -> ``(int, False)``."""
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        others = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
        return others[0], len(others) < len(typing.get_args(annotation))
    return annotation, False


def import_reward_modules(modules: Sequence[str]) -> None:
    """Import ``reward.modules``: module names or ``.py`` files that call ``register_reward``.

    Each is imported once per process, so a resumed run may import its saved list again.
    """
    for module in modules:
        if module.endswith(".py"):
            path = Path(module).resolve()
            if not path.is_file():
                raise FileNotFoundError(f"config reward.modules: {module!r} is not a file; pass "
                                        "the path of a .py file that registers rewards.")
            name = "reward_module_" + re.sub(r"\W", "_", str(path))
            if name not in sys.modules:
                spec = importlib.util.spec_from_file_location(name, path)
                loaded = importlib.util.module_from_spec(spec)
                sys.modules[name] = loaded
                try:
                    spec.loader.exec_module(loaded)
                except BaseException:
                    del sys.modules[name]
                    raise
        else:
            try:
                importlib.import_module(module)
            except ModuleNotFoundError as error:
                raise ValueError(f"config reward.modules: cannot import {module!r} ({error}); "
                                 "pass a module on PYTHONPATH or the path of a .py file."
                                 ) from error


def resolve_device(name: str, train_device: str | None = None) -> torch.device:
    """``auto`` -> CUDA when torch finds a GPU, else the CPU (for ``replay_buffer.device``:
    ``train_device``, resolved); any other name as a torch device, checked to exist.

    >>> resolve_device("cpu")
    device(type='cpu')
    """
    if name == "auto":
        if train_device is not None:
            return resolve_device(train_device)
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError) as error:
        raise ValueError("auto or a torch device such as cpu or cuda:0") from error
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("auto or cpu: torch finds no CUDA GPU on this machine")
    return device


def _device(cfg: DictConfig, key: str, train_device: str | None = None) -> torch.device:
    """``key``'s device, resolved; a ``ValueError`` naming the key when torch cannot use it."""
    try:
        return resolve_device(OmegaConf.select(cfg, key), train_device=train_device)
    except ValueError as error:
        raise _invalid(key, OmegaConf.select(cfg, key), str(error)) from error


@dataclasses.dataclass(frozen=True)
class Devices:
    """The torch devices of a training run's parts, resolved from its config's names (``auto``,
    ``cpu``, ``cuda:0`` ...) by one rule (:func:`resolve_device`; ``auto`` for the encoder and
    the replay: the train device's).

    The recipe's build resolves them once and hands them to every factory
    (:mod:`temporal_torchrl.training.factories`), so no two parts can disagree on where ``auto``
    is. The config keeps the names as given: config.json, the run directory and the resume
    checks do not depend on the machine a run starts on.

    Attributes:
        train: ``train.device``: the SAC agent, the reward and its heads, the policy, the SAC
            and finetuning batches, the evaluation's observations.
        encoder: ``encoder.device``: the frozen encoder.
        replay: ``replay_buffer.device``: the replay buffer's storage.
    """

    train: torch.device
    encoder: torch.device
    replay: torch.device

    @classmethod
    def of(cls, cfg: DictConfig) -> Devices:
        """The devices of a training config; a ``ValueError`` naming the key of a device torch
        cannot use (:func:`validate_recipe_config` checks them so)."""
        return cls(train=_device(cfg, "train.device"),
                   encoder=_device(cfg, "encoder.device", cfg.train.device),
                   replay=_device(cfg, "replay_buffer.device", cfg.train.device))


def _check_tasks(tasks: Sequence[Any], given: Any, expected: str) -> None:
    """Each of ``tasks`` (from ``env.task``, ``given``) a known task name."""
    if not tasks or any(not isinstance(task, str) or task not in TASKS for task in tasks):
        raise _invalid("env.task", given, f"{expected} ({len(TASKS)} known: see "
                       "temporal_torchrl.envs.TASKS)")


def _check_encoder_name(cfg: DictConfig) -> None:
    if cfg.encoder.name not in ENCODERS:
        raise _invalid("encoder.name", cfg.encoder.name, f"one of {', '.join(ENCODERS)}")


def _check_reward_names(key: str, names: Sequence[Any], registry: Mapping[str, Any],
                        given: Any, expected: str) -> None:
    """Each of ``names`` (``reward.<kind>``'s entries, ``given``) none or a registered name;
    ``expected``: how many (``one of``, ``a list of``)."""
    if any(not isinstance(name, str | None) or none_or_name(name) not in (None, *registry)
           for name in names):
        raise _invalid(key, given, f"none or {expected} {', '.join(registry)} (your own: "
                       "register_reward in a module listed in reward.modules)")


def _move_deprecated_keys(reward: DictConfig) -> list[str]:
    """Move what ``reward.window``, ``reward.certainty_bandwidth`` and ``reward.certainty_prior``
    (deprecated) set into ``reward.options`` (:func:`~temporal_torchrl.rewards.config.
    moved_options`), with a ``FutureWarning`` naming the new key for each, and leave the old
    keys null, so a run stores, names its directory by and resumes with its options in one
    place. A key at its old default is taken as not set, silently: every saved run's
    config.json holds the three. Returns the keys moved.

    Raises:
        ValueError: a key set both ways to different values, naming both.
    """
    moved = deprecated_settings(reward)
    reward.options = moved_options(reward)
    for key, value in moved.items():
        warnings.warn(
            f"config reward.{key}={value!r} is deprecated and read as reward.options.{key}="
            f"{value!r}; set that instead (+reward.options.{key}={value!r} on the command line, "
            f"reward.options.{key} in a resumed run's config.json). reward.{key} goes in the "
            "next release.", FutureWarning, stacklevel=3)
    for key in DEPRECATED_KEYS:
        reward[key] = None
    return list(moved)


def _check_reward_options(options: Mapping[str, Any], variants: Sequence[str],
                          certainty_scaling: bool = False, moved: Collection[str] = ()) -> None:
    """Each ``reward.options`` key an option one of ``variants`` (registered names) has (or,
    with ``certainty_scaling``, the scaling's), its value of the type (and, for the built-in
    options, in the range) of that option's default. ``moved``: the keys set by their
    deprecated spelling, which the message names."""
    declared = declared_options(variants, certainty_scaling)
    owners = [*variants, *(["certainty_scaling"] if certainty_scaling else [])]
    for key, value in options.items():
        spelled = f" (set as the deprecated reward.{key})" if key in moved else ""
        if key not in declared:
            raise _invalid(f"reward.options.{key}", value,
                           f"an option of {' or '.join(owners) or 'the reward'}: "
                           f"{', '.join(declared) or 'they declare none'} "
                           f"(register_reward(..., options=...) declares a reward's options)"
                           f"{spelled}")
        name, default = declared[key]
        try:
            option_value(name, key, value, default)
        except ValueError:
            raise _invalid(f"reward.options.{key}", value,
                           f"{option_expected(name, key, default)}{spelled}") from None


def _check_baseline(task: str, baseline: str) -> None:
    try:
        baseline_text(task, baseline)
    except ValueError as error:
        raise ValueError(f"config reward.baseline: {error}") from error


# --------------------------------------------------------------------------- the training recipe
def validate_recipe_config(cfg: DictConfig, source: str | None = None) -> DictConfig:
    """``recipes/sac_temporal.py``'s config, typed by
    :class:`~temporal_torchrl.configs.recipe.RecipeConfig` and checked; a ``ValueError`` naming
    the key on a bad value.

    Imports ``reward.modules`` first, so the rewards they register are known. ``source``: where
    the config came from, named by the error on a key the schema does not declare
    (:func:`check_declared_keys`).
    """
    check_declared_keys(cfg, RecipeConfig, source)
    cfg = typed(cfg, RecipeConfig)
    check_constraints(cfg, RecipeConfig)
    import_reward_modules(cfg.reward.modules)  # they may register the reward names checked below
    _check_tasks([cfg.env.task], cfg.env.task, "a Metaworld MT50 task name such as drawer-open")
    _check_encoder_name(cfg)
    for key, registry in (("positional", POSITIONAL), ("directional", DIRECTIONAL)):
        _check_reward_names(f"reward.{key}", [cfg.reward[key]], registry, cfg.reward[key],
                            "one of")
    moved = _move_deprecated_keys(cfg.reward)
    _check_reward_options(cfg.reward.options, [
        name for name in map(none_or_name, (cfg.reward.positional, cfg.reward.directional))
        if name is not None], cfg.reward.certainty_scaling, moved)
    longest = cfg.env.max_episode_steps + 1
    capacity = cfg.replay_buffer.capacity
    if capacity is not None and capacity < longest:
        raise _invalid("replay_buffer.capacity", capacity,
                       f"null (the whole run) or an integer >= {longest}, the rows of the longest "
                       "episode (its steps + 1), plus the rows of any preloaded experts")
    devices = Devices.of(cfg)  # a device torch cannot use: an error naming its key
    if cfg.compile.cudagraphs and devices.train.type != "cuda":
        raise _invalid("compile.cudagraphs", True, "false: CUDA graphs need a CUDA train.device")
    _check_baseline(cfg.env.task, cfg.reward.baseline)
    if cfg.train.positives_from == "":
        raise _invalid("train.positives_from", "", "null or the output_dir of a run trained "
                       "with train.save_positives=true")
    if cfg.reward.certainty_scaling and none_or_name(cfg.reward.directional) is None:
        raise _invalid("reward.certainty_scaling", True, "false without a directional reward "
                       "(it scales r_D), or a reward.directional such as d3")
    return cfg


# --------------------------------------------------------------------------- reward quality
def _as_list(value: Any) -> list:
    """A config value that may be one item or a list of them, as a list."""
    return list(value) if isinstance(value, ListConfig | list | tuple) else [value]


def config_tasks(cfg: DictConfig) -> list[str]:
    """The reward-quality recipe's ``env.task`` as a list of task names (one name or a list of
    them)."""
    return _as_list(cfg.env.task)


def config_variants(cfg: DictConfig) -> list[str]:
    """The reward-quality recipe's variants to score: ``reward.positional`` then
    ``reward.directional`` (``none`` dropped; either may be one name or a list)."""
    return [name for key in ("positional", "directional")
            for name in map(none_or_name, _as_list(cfg.reward[key])) if name is not None]


def validate_reward_quality_config(cfg: DictConfig) -> DictConfig:
    """``recipes/evaluate_rewards.py``'s config, typed by
    :class:`~temporal_torchrl.configs.reward_quality.RewardQualityConfig` and checked; a
    ``ValueError`` naming the key on a bad value.

    Imports ``reward.modules`` first, so the rewards they register are known.
    """
    check_declared_keys(cfg, RewardQualityConfig)
    cfg = typed(cfg, RewardQualityConfig)
    check_constraints(cfg, RewardQualityConfig)
    import_reward_modules(cfg.reward.modules)
    tasks = config_tasks(cfg)
    _check_tasks(tasks, cfg.env.task, "a Metaworld MT50 task name such as drawer-open, or a "
                 "list of them")
    _check_encoder_name(cfg)
    for key, registry in (("positional", POSITIONAL), ("directional", DIRECTIONAL)):
        names = _as_list(cfg.reward[key])
        _check_reward_names(f"reward.{key}", names, registry, names, "a list of")
    if not config_variants(cfg):
        raise _invalid("reward.positional", cfg.reward.positional,
                       "at least one variant to score in reward.positional or reward.directional")
    moved = _move_deprecated_keys(cfg.reward)
    _check_reward_options(cfg.reward.options, config_variants(cfg), moved=moved)
    if max(cfg.dataset.random_episodes, cfg.dataset.failed_expert_episodes) < 2:
        raise _invalid("dataset.random_episodes", cfg.dataset.random_episodes,
                       "random_episodes >= 2 or failed_expert_episodes >= 2 (the split holds out "
                       "episodes of each kind, and a kind needs 2 to appear in both the training "
                       "and the held-out part)")
    if cfg.env.goal != defaults.FIXED_GOAL:
        raise _invalid("env.goal", cfg.env.goal,
                       f"{defaults.FIXED_GOAL}: the benchmark scores episodes on the seed's "
                       "layout (random goals are a training setting)")
    for task in tasks:
        _check_baseline(task, cfg.reward.baseline)
    _device(cfg, "encoder.device")
    return cfg
