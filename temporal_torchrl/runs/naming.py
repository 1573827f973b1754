"""A run's default directory: named from what distinguishes it from other runs."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from temporal_torchrl import defaults
from temporal_torchrl.rewards.config import moved_options, uses_vlm_reward
from temporal_torchrl.runs.layout import protocol_name

#: What a default run directory's name tells runs apart by (:func:`default_run_dir`).
NAMED_BY = "task, encoder, reward, rho, lambda, baseline, reward options, protocol and seed"


def default_run_dir(cfg: DictConfig) -> Path:
    """``runs/<task>/<encoder>_<positional>+<directional>_rho<r>_lambda<l>_<baseline>_<protocol>
    /seed<s>``: runs that differ in anything a preset or protocol sets (encoder, reward, rho,
    lambda, baseline, preloaded experts), in a reward option or in the seed never share a
    directory (with ``reward.certainty_scaling`` the directional part reads
    ``<directional>xcertainty``; with ``reward.options`` the baseline is followed by
    ``_opt<digest>``, :func:`options_digest`, of the options set, not of their defaults, so a
    run of d_sequence's or d_certainty's default options keeps the name it had before they
    became options (their deprecated keys, null or at their old default, set none); with
    ``env.goal=random`` the protocol part ends in ``_randomgoal``). Each suffix appears only
    when its setting is on, so the names of runs without it, older ones included, stay as they
    were and those runs still resume."""
    if uses_vlm_reward(cfg):
        baseline = cfg.reward.baseline
        if baseline not in ("generic", "tailored"):
            baseline = re.sub(r"[^A-Za-z0-9]+", "-", baseline).strip("-")[:40] or "text"
        scaled = "xcertainty" if cfg.reward.certainty_scaling else ""
        # The options as validation stores them (reward.window=12 is reward.options.window=12),
        # so a sweep job's directory is the same before its config is validated and after.
        options = moved_options(OmegaConf.to_container(cfg.reward, resolve=True))
        tagged = f"_opt{options_digest(options)}" if options else ""
        method = (f"{cfg.encoder.name}_{cfg.reward.positional}+{cfg.reward.directional}{scaled}"
                  f"_rho{cfg.reward.rho:g}_lambda{cfg.reward.lambda_:g}_{baseline}{tagged}")
    else:
        method = "sac"
    protocol = protocol_name(cfg.train.preload_positives)
    if cfg.env.get("goal", defaults.FIXED_GOAL) == "random":
        protocol += "_randomgoal"
    root = Path(cfg.runs_dir) if cfg.runs_dir is not None else Path("runs")
    return root / cfg.env.task / f"{method}_{protocol}" / f"seed{cfg.env.seed}"


def options_digest(options: dict[str, Any]) -> str:
    """8 hex digits of the SHA-256 of ``options`` (``reward.options``) as sorted, compact JSON:
    short enough for a path, the same on every machine and Python, and different for any
    option's value, so a sweep over a reward's option gives each value a run directory. A
    float with an integral value counts as that integer (the reward takes an integer for a
    float option), so ``sharpness=2`` and ``sharpness=2.0``, one reward, share a directory."""
    canonical = {name: int(value) if isinstance(value, float) and value.is_integer() else value
                 for name, value in options.items()}
    text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def run_directory(cfg: DictConfig) -> Path:
    """``output_dir``, or (null) :func:`default_run_dir`."""
    return Path(cfg.output_dir) if cfg.output_dir is not None else default_run_dir(cfg)
