"""The training recipe's config (``recipes/config.yaml``): validation, devices, replay capacity.

:func:`validate_config` stops a run before any work on a bad value, naming the key. A run's
directory, its resume and its sweep jobs are :mod:`temporal_torchrl.runs`' business.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf

from temporal_torchrl.encoders import ENCODERS
from temporal_torchrl.envs import TASKS, baseline_text
from temporal_torchrl.rewards import DIRECTIONAL, POSITIONAL
from temporal_torchrl.runs import none_or_name

LOGGER_BACKENDS = ("wandb", "csv", "none")


def _integer(minimum: int) -> tuple[Callable[[Any], bool], str]:
    return (lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= minimum,
            f"an integer >= {minimum}")


def _number(test: Callable[[float], bool], expected: str) -> tuple[Callable[[Any], bool], str]:
    return (lambda v: isinstance(v, int | float) and not isinstance(v, bool) and test(v),
            expected)


#: (key, check, what is expected, whether null is allowed) for the numeric settings.
_NUMERIC_CHECKS = (
    ("env.max_episode_steps", *_integer(1), False),
    ("env.num_envs", *_integer(1), False),
    ("reward.rho", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("reward.lambda_", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("reward.k", *_integer(1), False),
    ("reward.alpha", *_number(lambda v: 0 <= v <= 1, "a number in [0, 1]"), False),
    ("reward.delta", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("reward.l2_margin", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("reward.gap", *_integer(1), False),
    ("reward.batch_size", *_integer(1), False),
    ("reward.lr", *_number(lambda v: v > 0, "a number > 0"), False),
    ("reward.label_window", *_integer(1), True),
    ("reward.window", *_integer(2), False),
    ("reward.certainty_bandwidth", *_number(lambda v: v > 0, "a number > 0"), False),
    ("reward.certainty_prior", *_number(lambda v: v > 0, "a number > 0"), False),
    ("sac.batch_size", *_integer(1), False),
    ("sac.lr", *_number(lambda v: v > 0, "a number > 0"), False),
    ("sac.gamma", *_number(lambda v: 0 < v <= 1, "a number in (0, 1]"), False),
    ("sac.tau", *_number(lambda v: 0 < v <= 1, "a number in (0, 1]"), False),
    ("sac.alpha_init", *_number(lambda v: v > 0, "a number > 0"), False),
    ("sac.target_entropy", *_number(lambda v: True, "a number"), True),
    ("train.episodes", *_integer(1), False),
    ("train.preload_positives", *_integer(0), False),
    ("train.expert_steps_after_success", *_integer(0), True),
    ("train.random_steps", *_integer(0), False),
    ("train.utd_ratio", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("train.reward_updates_per_step", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("train.relay_noise", *_number(lambda v: v >= 0, "a number >= 0"), False),
    ("train.relay_threshold", *_integer(0), False),
    ("train.checkpoint_every", *_integer(1), False),
    ("train.stop_after_episodes", *_integer(1), True),
    ("train.threads", *_integer(1), True),
    ("logger.log_every", *_integer(1), False),
)


_GROUPS = ("env", "encoder", "reward", "sac", "replay_buffer", "train", "compile", "logger")
#: torch.compile's modes (null: its default).
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")


EMBEDDING_DTYPES = ("float16", "bfloat16", "float32")


def import_reward_modules(modules: Sequence[str]) -> None:
    """Import ``reward.modules``: module names or ``.py`` files that call ``register_reward``.

    Each is imported once per process, so a resumed run may import its saved list again.
    """
    if isinstance(modules, str) or not all(isinstance(module, str) for module in modules):
        raise ValueError(f"config reward.modules={modules!r} is invalid: expected a list of "
                         "module names or .py files, e.g. reward.modules=[my_rewards.py].")
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


def validate_config(cfg: DictConfig) -> None:
    """Stop before any work on a bad value, naming the config key (ValueError).

    Imports ``reward.modules`` first, so the rewards they register are known.
    """
    def bad(key: str, value: Any, expected: str) -> ValueError:
        return ValueError(f"config {key}={value!r} is invalid: expected {expected}. "
                          f"Fix it on the command line, e.g. {key}=<value>.")

    for group in _GROUPS:
        value = cfg.get(group)
        if not isinstance(value, DictConfig):
            hint = (f"did you mean encoder.name={value}?" if group == "encoder" else
                    f"set its keys one by one, e.g. {group}.<key>=<value>")
            raise bad(group, value, f"a group of settings ({hint})")
    import_reward_modules(cfg.reward.modules)  # they may register the reward names checked below
    if cfg.env.task not in TASKS:
        raise bad("env.task", cfg.env.task, "a Metaworld MT50 task name such as "
                  f"drawer-open ({len(TASKS)} known: see temporal_torchrl.envs.TASKS)")
    if cfg.encoder.name not in ENCODERS:
        raise bad("encoder.name", cfg.encoder.name, f"one of {', '.join(ENCODERS)}")
    positional = none_or_name(cfg.reward.positional)
    directional = none_or_name(cfg.reward.directional)
    if positional is not None and positional not in POSITIONAL:
        raise bad("reward.positional", cfg.reward.positional,
                  f"none or one of {', '.join(POSITIONAL)} (your own: register_reward in a "
                  "module listed in reward.modules)")
    if directional is not None and directional not in DIRECTIONAL:
        raise bad("reward.directional", cfg.reward.directional,
                  f"none or one of {', '.join(DIRECTIONAL)} (your own: register_reward in a "
                  "module listed in reward.modules)")
    for key, ok, expected, nullable in _NUMERIC_CHECKS:
        value = OmegaConf.select(cfg, key)
        if not (value is None and nullable) and not ok(value):
            raise bad(key, value, expected + (", or null" if nullable else ""))
    hidden = cfg.sac.hidden_sizes
    if not hidden or not all(_integer(1)[0](size) for size in hidden):
        raise bad("sac.hidden_sizes", hidden, "a list of integers >= 1, e.g. [256,256]")
    if cfg.replay_buffer.embedding_dtype not in EMBEDDING_DTYPES:
        raise bad("replay_buffer.embedding_dtype", cfg.replay_buffer.embedding_dtype,
                  f"one of {', '.join(EMBEDDING_DTYPES)}")
    longest = cfg.env.max_episode_steps + 1
    capacity = cfg.replay_buffer.capacity
    if capacity is not None and not (_integer(longest)[0](capacity)):
        raise bad("replay_buffer.capacity", capacity,
                  f"null (the whole run) or an integer >= {longest}, the rows of the longest "
                  "episode (its steps + 1), plus the rows of any preloaded experts")
    for key in ("train.device", "encoder.device", "replay_buffer.device"):
        try:
            resolve_device(OmegaConf.select(cfg, key), train_device=cfg.train.device)
        except ValueError as error:
            raise bad(key, OmegaConf.select(cfg, key), str(error)) from error
    for key in ("compile.enabled", "compile.cudagraphs"):
        if not isinstance(OmegaConf.select(cfg, key), bool):
            raise bad(key, OmegaConf.select(cfg, key), "true or false")
    if cfg.compile.mode is not None and cfg.compile.mode not in COMPILE_MODES:
        raise bad("compile.mode", cfg.compile.mode, f"null or one of {', '.join(COMPILE_MODES)}")
    if cfg.compile.cudagraphs and resolve_device(cfg.train.device).type != "cuda":
        raise bad("compile.cudagraphs", True, "false: CUDA graphs need a CUDA train.device")
    if cfg.logger.backend not in LOGGER_BACKENDS:
        raise bad("logger.backend", cfg.logger.backend, f"one of {', '.join(LOGGER_BACKENDS)}")
    try:
        baseline_text(cfg.env.task, cfg.reward.baseline)
    except ValueError as error:
        raise ValueError(f"config reward.baseline: {error}") from error
    for key in ("train.relay", "train.save_positives"):
        if not isinstance(OmegaConf.select(cfg, key), bool):
            raise bad(key, OmegaConf.select(cfg, key), "true or false")
    periods = cfg.train.relay_periods
    if not periods or not all(_integer(1)[0](period) for period in periods):
        raise bad("train.relay_periods", periods,
                  "a list of integers >= 1 (the release's: [50,100,150,200])")
    source = cfg.train.positives_from
    if source is not None and (not isinstance(source, str) or not source):
        raise bad("train.positives_from", source, "null or the output_dir of a run trained with "
                  "train.save_positives=true")
    if not isinstance(cfg.reward.certainty_scaling, bool):
        raise bad("reward.certainty_scaling", cfg.reward.certainty_scaling, "true or false")
    if cfg.reward.certainty_scaling and directional is None:
        raise bad("reward.certainty_scaling", True, "false without a directional reward (it "
                  "scales r_D), or a reward.directional such as d3")


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


def replay_capacity(cfg: DictConfig, expert_rows: int = 0, saved: int | None = None) -> int:
    """Buffer rows: ``replay_buffer.capacity``, or (null) the whole run, every training episode
    plus ``expert_rows``, capped at 1,000,000. A resumed run never shrinks its ``saved``
    capacity, and grows it (saying so) when it was extended."""
    capacity = cfg.replay_buffer.capacity
    if capacity is None:
        capacity = min(cfg.train.episodes * (cfg.env.max_episode_steps + 1) + expert_rows,
                       1_000_000)
    if capacity - expert_rows < cfg.env.max_episode_steps + 1:
        raise ValueError(f"config replay_buffer.capacity={capacity} is invalid: the preloaded "
                         f"experts take {expert_rows} rows and an episode up to "
                         f"{cfg.env.max_episode_steps + 1}; raise it (or set null).")
    if saved is not None and capacity > saved:
        print(f"resume: replay capacity grown from {saved:,} to {capacity:,} rows for "
              f"train.episodes={cfg.train.episodes}")
    return max(capacity, saved or 0)

