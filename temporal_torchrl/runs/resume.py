"""Continuing a run: the config it resumes with, the keys a process may change, the other
config's run it must not continue, sweep jobs that resume their runs, and positives one run
gives another."""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from temporal_torchrl import defaults
from temporal_torchrl.rewards.config import DEPRECATED_KEYS, uses_vlm_reward, with_moved_options
from temporal_torchrl.runs.directory import RunDirectory
from temporal_torchrl.runs.layout import CONFIG_FILE, SUMMARY_FILE, flatten
from temporal_torchrl.runs.naming import NAMED_BY, run_directory


def sweep_job_config(cfg: DictConfig, hydra_config: DictConfig) -> DictConfig | None:
    """One job of a ``-m`` sweep: its run directory under the sweep directory, resumed when a
    checkpoint is there (a re-launched sweep continues its runs, finished ones return at once),
    None (nothing to run) when the directory holds a finished run's raw files without its
    checkpoint (a study's committed runs copied back into the sweep on a new machine),
    restarted when the job died before its first checkpoint, and torch threads set so that
    parallel jobs share the cores instead of oversubscribing them. A run a live process is
    writing is left as it is: the recipe's ``train`` then stops on its lock (``RunLockedError``)."""
    cfg = copy.deepcopy(cfg)
    if cfg.runs_dir is None:
        cfg.runs_dir = hydra_config.sweep.dir
    run = RunDirectory(run_directory(cfg))
    if not cfg.overwrite and not cfg.resume and run.locked_by() is None:
        if finished_without_checkpoint(run, cfg.train.episodes):
            print(f"{run.path}: already complete ({SUMMARY_FILE} without a checkpoint: skipped)")
            return None
        if run.has_checkpoint():
            cfg.resume = True
        elif run.holds_files():
            print(f"{run.path}: no checkpoint yet, starting it over")
            cfg.overwrite = True
    if cfg.train.threads is None:
        cfg.train.threads = threads_per_job(hydra_config.launcher)
    return cfg


def finished_without_checkpoint(run: RunDirectory, episodes: int) -> bool:
    """Whether ``run`` holds the summary of a run of at least ``episodes`` episodes but no
    checkpoint: finished, with only the raw files a study commits."""
    summary = run.summary()
    return (summary is not None and not run.has_checkpoint()
            and summary.get("episodes", 0) >= episodes)


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
#: other value comes from the run's saved config.json. Compilation is among them: compiled and
#: eager give the same episodes within float tolerance (tested), so a long run started eager may
#: go on compiled, or a run whose compiler fails on a new machine go on eager.
RESUMABLE_KEYS = ("train.episodes", "train.checkpoint_every", "compile.enabled", "compile.mode",
                  "compile.cudagraphs")
#: Where a run computes: the same run on another device (the reports group them as one).
DEVICE_KEYS = ("encoder.device", "train.device", "replay_buffer.device")


class RunConflictError(ValueError):
    """A run asked for values that differ from those of the run already in its directory.

    A run directory holds one run, named by what presets and protocols change and by the reward's
    own options (:data:`~temporal_torchrl.runs.naming.NAMED_BY`), so two runs that differ only
    in another key (``sac.lr``, ``reward.alpha``, ...) map to one directory: the second would
    resume the first instead of running. ``conflicts`` maps each such key to (asked for, in
    the directory).
    """

    def __init__(self, path: Path, conflicts: dict[str, tuple[Any, Any]],
                 other: str = "the run there") -> None:
        self.path, self.conflicts = path, conflicts
        asked = ", ".join(f"{key}={value!r}" for key, (value, _) in conflicts.items())
        theirs = ", ".join(f"{key}={value!r}" for key, (_, value) in conflicts.items())
        keys = "".join(f"_{key.rsplit('.', 1)[-1]}${{{key}}}" for key in conflicts)
        super().__init__(
            f"{path} holds another config's run: this run asks for {asked}, {other} has "
            f"{theirs}. A run directory's name tells runs apart by {NAMED_BY}, not by "
            f"{', '.join(conflicts)}, so this run "
            "would continue that one instead of running. Give each value a directory of its "
            f"own: output_dir='${{hydra:sweep.dir}}/${{env.task}}{keys}/seed${{env.seed}}' in a "
            "sweep, output_dir=<a new directory> for a single run.")


def _is_given(key: str, given_keys: Collection[str]) -> bool:
    """Whether the flattened config ``key`` was set by one of ``given_keys`` (itself, a group
    above it, or a key inside it)."""
    return any(key == given or key.startswith(f"{given}.") or given.startswith(f"{key}.")
               for given in given_keys)


def check_no_conflict(cfg: DictConfig, run: RunDirectory,
                      given_keys: Collection[str] | None) -> None:
    """Raise :class:`RunConflictError` when ``run`` holds a run whose config differs from
    ``cfg`` in a key set on the command line (``given_keys``; None, a config built in code,
    checks nothing): resuming or replacing it would not run what was asked for."""
    if cfg.overwrite or given_keys is None or not (run.path / CONFIG_FILE).is_file():
        return
    conflicts = conflicting_values(cfg, run.config(), given_keys)
    if conflicts:
        raise RunConflictError(run.path, conflicts)


def conflicting_values(cfg: DictConfig, other: dict[str, Any],
                       given_keys: Collection[str]) -> dict[str, tuple[Any, Any]]:
    """The keys of ``given_keys`` whose values in ``cfg`` differ from those in the config
    ``other``, except the keys one run may change between its processes (process, resumable,
    device and logger keys): ``{key: (cfg's value, other's value)}``. Both are compared as
    validation spells them (:func:`~temporal_torchrl.rewards.config.with_moved_options`), so a
    run saved with ``reward.window: 8`` is not another config's, and a deprecated key given
    (``reward.window``) is compared as the option it sets."""
    ours = flatten(with_moved_options(OmegaConf.to_container(cfg, resolve=True)))
    theirs = flatten(with_moved_options(other))
    given_keys = {*given_keys, *(f"reward.options.{key}" for key in DEPRECATED_KEYS
                                 if f"reward.{key}" in given_keys)}
    return {key: (value, theirs[key]) for key, value in ours.items()
            if key in theirs and theirs[key] != value and _is_given(key, given_keys)
            and key not in (*PROCESS_KEYS, *RESUMABLE_KEYS, *DEVICE_KEYS)
            and not key.startswith("logger.")}


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
    saved = OmegaConf.merge(current, json.loads((run_dir / CONFIG_FILE).read_text()))
    applied = [*PROCESS_KEYS, *(key for key in RESUMABLE_KEYS
                               if given_keys is None or key in given_keys)]
    for key in applied:
        OmegaConf.update(saved, key, OmegaConf.select(cfg, key), force_add=True)
    saved_values = flatten(with_moved_options(OmegaConf.to_container(saved, resolve=True)))
    current_values = flatten(with_moved_options(OmegaConf.to_container(cfg, resolve=True)))
    differing = [key for key, value in current_values.items()
                 if key not in applied and saved_values.get(key, value) != value]
    if differing:
        print(f"resume: continuing with {run_dir / CONFIG_FILE}; not using the current "
              f"values of {', '.join(differing)}")
    return saved


#: What a run giving its saved positives to another must share with it: the layout always, the
#: frames and the encoder when the receiving run embeds them.
_LAYOUT_KEYS = ("env.task", "env.seed", "env.goal")
#: What a key a source run's config.json lacks meant then (runs from before the key existed).
BEFORE_THE_KEY = {"env.goal": defaults.FIXED_GOAL}
#: What makes a run's frames and their embeddings: unread by a run without a VLM reward.
FRAME_KEYS = ("env.image_size", "env.camera", "env.fast_render", "encoder.name",
               "encoder.checkpoint", "encoder.options")


def check_positives_source(cfg: DictConfig, source_config: dict[str, Any]) -> None:
    """Raise unless the run in ``train.positives_from`` (its saved ``source_config``) made its
    positives with this run's task, layout and, when this run has a VLM reward, frames and
    encoder."""
    source = OmegaConf.create(source_config)
    keys = _LAYOUT_KEYS + (FRAME_KEYS if uses_vlm_reward(cfg) else ())
    if uses_vlm_reward(cfg) and not uses_vlm_reward(source):
        raise ValueError(f"config train.positives_from={cfg.train.positives_from!r} is a run "
                         "without a VLM reward: its positives carry no embeddings. Take them "
                         "from a run with this run's encoder.")
    for key in keys:
        theirs = OmegaConf.select(source, key, default=BEFORE_THE_KEY.get(key))
        ours = OmegaConf.select(cfg, key)
        if isinstance(theirs, DictConfig):
            theirs, ours = OmegaConf.to_container(theirs), OmegaConf.to_container(ours)
        if theirs != ours:
            raise ValueError(
                f"config train.positives_from={cfg.train.positives_from!r} was trained with "
                f"{key}={theirs!r}, this run has {key}={ours!r}: preloaded positives must come "
                "from the same task, layouts (env.seed, env.goal), frames and encoder. Use a "
                f"source run with {key}={ours!r}.")
