"""The training recipe's config (``recipes/config.yaml``): validation, run directories, resume.

- :func:`validate_config` stops a run before any work on a bad value, naming the key;
- :func:`default_run_dir` names a run's directory from what distinguishes it;
- :func:`resumed_config` continues a run with the config it started with;
- :func:`sweep_job_config` makes each job of a ``-m`` sweep resumable and sets its threads.
"""

from __future__ import annotations

import copy
import importlib
import importlib.util
import json
import os
import re
import sys
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf

from temporal_torchrl.encoders import ENCODERS
from temporal_torchrl.envs import TASKS, baseline_text
from temporal_torchrl.rewards import DIRECTIONAL, POSITIONAL
from temporal_torchrl.training.run import RunDirectory

LOGGER_BACKENDS = ("wandb", "csv", "none")


#: Expert episodes the thesis preloads in its second stage (protocol=stage2).
STAGE2_EXPERTS = 50


def none_or_name(value: Any) -> str | None:
    """A reward name from the config, None for null or "none"."""
    return None if value is None or str(value).lower() == "none" else str(value)


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


#: What a run giving its saved positives to another must share with it: the layout always, the
#: frames and the encoder when the receiving run embeds them.
_LAYOUT_KEYS = ("env.task", "env.seed")
_FRAME_KEYS = ("env.image_size", "env.camera", "env.fast_render", "encoder.name",
               "encoder.checkpoint", "encoder.options")


def check_positives_source(cfg: DictConfig, source_config: dict[str, Any]) -> None:
    """Raise unless the run in ``train.positives_from`` (its saved ``source_config``) made its
    positives with this run's task, layout and, when this run has a VLM reward, frames and
    encoder."""
    source = OmegaConf.create(source_config)
    keys = _LAYOUT_KEYS + (_FRAME_KEYS if uses_vlm_reward(cfg) else ())
    if uses_vlm_reward(cfg) and not uses_vlm_reward(source):
        raise ValueError(f"config train.positives_from={cfg.train.positives_from!r} is a run "
                         "without a VLM reward: its positives carry no embeddings. Take them "
                         "from a run with this run's encoder.")
    for key in keys:
        theirs, ours = OmegaConf.select(source, key), OmegaConf.select(cfg, key)
        if isinstance(theirs, DictConfig):
            theirs, ours = OmegaConf.to_container(theirs), OmegaConf.to_container(ours)
        if theirs != ours:
            raise ValueError(
                f"config train.positives_from={cfg.train.positives_from!r} was trained with "
                f"{key}={theirs!r}, this run has {key}={ours!r}: preloaded positives must come "
                "from the same task, layout (env.seed), frames and encoder. Use a source run "
                f"with {key}={ours!r}.")


def uses_vlm_reward(cfg: DictConfig) -> bool:
    return (none_or_name(cfg.reward.positional) is not None
            or none_or_name(cfg.reward.directional) is not None)


def default_run_dir(cfg: DictConfig) -> Path:
    """``runs/<task>/<encoder>_<positional>+<directional>_rho<r>_lambda<l>_<baseline>_<protocol>
    /seed<s>``: runs that differ in anything a preset or protocol sets (encoder, reward, rho,
    lambda, baseline, preloaded experts) or in the seed never share a directory (with
    ``reward.certainty_scaling`` the directional part reads ``<directional>xcertainty``)."""
    if uses_vlm_reward(cfg):
        baseline = cfg.reward.baseline
        if baseline not in ("generic", "tailored"):
            baseline = re.sub(r"[^A-Za-z0-9]+", "-", baseline).strip("-")[:40] or "text"
        scaled = "xcertainty" if cfg.reward.certainty_scaling else ""
        method = (f"{cfg.encoder.name}_{cfg.reward.positional}+{cfg.reward.directional}{scaled}"
                  f"_rho{cfg.reward.rho:g}_lambda{cfg.reward.lambda_:g}_{baseline}")
    else:
        method = "sac"
    preload = cfg.train.preload_positives
    protocol = {0: "stage1", STAGE2_EXPERTS: "stage2"}.get(preload, f"preload{preload}")
    root = Path(cfg.runs_dir) if cfg.runs_dir is not None else Path("runs")
    return root / cfg.env.task / f"{method}_{protocol}" / f"seed{cfg.env.seed}"


def run_directory(cfg: DictConfig) -> Path:
    """``output_dir``, or (null) :func:`default_run_dir`."""
    return Path(cfg.output_dir) if cfg.output_dir is not None else default_run_dir(cfg)


def sweep_job_config(cfg: DictConfig, hydra_config: DictConfig) -> DictConfig:
    """One job of a ``-m`` sweep: its run directory under the sweep directory, resumed when a
    checkpoint is there (a re-launched sweep continues its runs, finished ones return at once),
    restarted when the job died before its first checkpoint, and torch threads set so that
    parallel jobs share the cores instead of oversubscribing them. A run a live process is
    writing is left as it is: :func:`train` then stops on its lock (``RunLockedError``)."""
    cfg = copy.deepcopy(cfg)
    if cfg.runs_dir is None:
        cfg.runs_dir = hydra_config.sweep.dir
    run = RunDirectory(run_directory(cfg))
    if not cfg.overwrite and not cfg.resume and run.locked_by() is None:
        if run.has_checkpoint():
            cfg.resume = True
        elif run.holds_files():
            print(f"{run.path}: no checkpoint yet, starting it over")
            cfg.overwrite = True
    if cfg.train.threads is None:
        cfg.train.threads = threads_per_job(hydra_config.launcher)
    return cfg


def threads_per_job(launcher: DictConfig) -> int | None:
    """Cores / parallel jobs for the joblib launcher (``n_jobs`` -1 or null: one per core);
    None (torch's default) for the others: Slurm gives each job its own CPUs."""
    if "n_jobs" not in launcher:
        return None
    cores = os.cpu_count() or 1
    jobs = launcher.n_jobs if launcher.n_jobs not in (None, -1) and launcher.n_jobs > 0 else cores
    return max(1, cores // min(jobs, cores))


#: Keys about this process, not the run (where and how to resume, when to stop, the progress bar,
#: threads): a resumed run always takes their current values.
PROCESS_KEYS = ("resume", "overwrite", "output_dir", "runs_dir", "train.stop_after_episodes",
                "train.progress", "train.threads")


#: Keys of the run a resumed run may change when they are given on the command line; every
#: other value comes from the run's saved config.json.
RESUMABLE_KEYS = ("train.episodes", "train.checkpoint_every")


def override_keys(overrides: Sequence[str]) -> set[str]:
    """The config keys that command-line overrides set (``+``, ``++`` and ``~`` dropped)."""
    return {override.split("=", 1)[0].lstrip("+~") for override in overrides}


def resumed_config(cfg: DictConfig, run_dir: Path,
                   given_keys: Collection[str] | None = None) -> DictConfig:
    """The config of the run in ``run_dir``, continued with ``cfg``'s :data:`PROCESS_KEYS`.

    A resumed run must go on with the task, encoder, reward and hyperparameters it started with,
    whatever the command line's defaults are now; so ``resume=true output_dir=...`` is enough.
    Of :data:`RESUMABLE_KEYS`, ``cfg``'s values replace the saved ones only for ``given_keys``
    (the keys set on the command line), or all of them when ``given_keys`` is None (a config
    built in code). Keys the saved config lacks (added to the recipe after the run started) take
    ``cfg``'s values.
    """
    current = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True))
    saved = OmegaConf.merge(current, json.loads((run_dir / "config.json").read_text()))
    applied = [*PROCESS_KEYS, *(key for key in RESUMABLE_KEYS
                               if given_keys is None or key in given_keys)]
    for key in applied:
        OmegaConf.update(saved, key, OmegaConf.select(cfg, key), force_add=True)
    saved_values = _flatten(saved)
    differing = [key for key, value in _flatten(cfg).items()
                 if key not in applied and saved_values.get(key, value) != value]
    if differing:
        print(f"resume: continuing with {run_dir / 'config.json'}; not using the current "
              f"values of {', '.join(differing)}")
    return saved


def _flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, DictConfig):
        tree = OmegaConf.to_container(tree, resolve=True)
    if not isinstance(tree, dict):
        return {prefix: tree}
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        flat.update(_flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    return flat


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

