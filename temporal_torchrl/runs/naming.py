"""A run's default directory: named from what distinguishes it from other runs."""

from __future__ import annotations

import re
from pathlib import Path

from omegaconf import DictConfig

from temporal_torchrl.rewards.config import uses_vlm_reward
from temporal_torchrl.runs.layout import protocol_name

#: What a default run directory's name tells runs apart by (:func:`default_run_dir`).
NAMED_BY = "task, encoder, reward, rho, lambda, baseline, protocol and seed"


def default_run_dir(cfg: DictConfig) -> Path:
    """``runs/<task>/<encoder>_<positional>+<directional>_rho<r>_lambda<l>_<baseline>_<protocol>
    /seed<s>``: runs that differ in anything a preset or protocol sets (encoder, reward, rho,
    lambda, baseline, preloaded experts) or in the seed never share a directory (with
    ``reward.certainty_scaling`` the directional part reads ``<directional>xcertainty``; with
    ``env.goal=random`` the protocol part ends in ``_randomgoal``)."""
    if uses_vlm_reward(cfg):
        baseline = cfg.reward.baseline
        if baseline not in ("generic", "tailored"):
            baseline = re.sub(r"[^A-Za-z0-9]+", "-", baseline).strip("-")[:40] or "text"
        scaled = "xcertainty" if cfg.reward.certainty_scaling else ""
        method = (f"{cfg.encoder.name}_{cfg.reward.positional}+{cfg.reward.directional}{scaled}"
                  f"_rho{cfg.reward.rho:g}_lambda{cfg.reward.lambda_:g}_{baseline}")
    else:
        method = "sac"
    protocol = protocol_name(cfg.train.preload_positives)
    if cfg.env.get("goal", "fixed") == "random":
        protocol += "_randomgoal"
    root = Path(cfg.runs_dir) if cfg.runs_dir is not None else Path("runs")
    return root / cfg.env.task / f"{method}_{protocol}" / f"seed{cfg.env.seed}"


def run_directory(cfg: DictConfig) -> Path:
    """``output_dir``, or (null) :func:`default_run_dir`."""
    return Path(cfg.output_dir) if cfg.output_dir is not None else default_run_dir(cfg)
