"""A finished run's ``summary.json``: the thesis's scores and how the run went."""

from __future__ import annotations

from typing import Any

from omegaconf import DictConfig, OmegaConf

from temporal_torchrl.envs import get_task
from temporal_torchrl.protocol_metrics import DEFAULT_HORIZON, DEFAULT_WINDOW, ras, tt50s, ttfs
from temporal_torchrl.runs.evaluation_log import evaluation_summary
from temporal_torchrl.training.state import TrainingProgress


def run_summary(cfg: DictConfig, progress: TrainingProgress, *, steps_per_second: float,
                encoder: str | None, relay_steps: int,
                phase_seconds: dict[str, float] | None = None,
                evaluations: list[dict[str, float]] | None = None,
                provenance: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """TTFS and TT50S (the horizon when never reached), RAS with the task's episode budget
    (None until the run has reached it), the counters, the throughput, the seconds per phase of
    the loop (:mod:`~temporal_torchrl.training.timing`; this process's), the last training
    metrics, the resolved config, where each of its starts ran (``provenance``:
    :mod:`~temporal_torchrl.runs.provenance`'s entries) and, with ``evaluations``
    (``eval.csv``'s rows), the last and the best evaluation (None without)."""
    successes = progress.successes
    budget = get_task(cfg.env.task).ras_budget
    # RAS's window (thesis 5.1), shortened to a budget below it
    window = min(DEFAULT_WINDOW, budget) if budget else DEFAULT_WINDOW
    return {
        "ttfs": ttfs(successes), "tt50s": tt50s(successes), "horizon": DEFAULT_HORIZON,
        "ras": {"value": ras(successes, budget, window) if budget else None,
                "budget": budget, "window": window},
        "episodes": progress.episode, "env_steps": progress.env_steps,
        "successes": int(sum(successes)), "steps_per_second": steps_per_second,
        "encoder": encoder, "updates": progress.updates, "last_metrics": progress.last_metrics,
        "relay_steps": relay_steps, "phase_seconds": phase_seconds or {},
        "config": OmegaConf.to_container(cfg, resolve=True), "provenance": provenance or [],
        "evaluation": evaluation_summary(evaluations or [])}
