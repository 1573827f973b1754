"""The schema of ``recipes/evaluate_rewards.py``'s config (``recipes/evaluate_rewards.yaml``).

``env.*``, ``encoder.*`` and ``reward.*`` are the training recipe's
(:mod:`temporal_torchrl.configs.recipe`), but for the keys that take several values here:
``env.task`` a task name or a list of them, ``reward.positional`` and ``reward.directional`` a
variant or a list of variants (each checked by :mod:`temporal_torchrl.configs.rules`). What
each key means is documented once, in ``evaluate_rewards.yaml``'s comments.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl.configs.fields import constrained
from temporal_torchrl.configs.recipe import EncoderConfig, SharedEnvConfig, SharedRewardConfig


@dataclass
class RewardQualityEnvConfig(SharedEnvConfig):
    """``env.*``; ``task`` may be a list of task names (one table per task)."""

    task: Any = "drawer-open"


@dataclass
class RewardQualityEncoderConfig(EncoderConfig):
    """``encoder.*``, on the CPU unless told otherwise."""

    device: str = "cpu"


@dataclass
class RewardQualityRewardConfig(SharedRewardConfig):
    """``reward.*``; every variant listed in ``positional`` and ``directional`` is scored."""

    positional: Any = field(default_factory=lambda: ["liv", "furl", "p1", "p2", "p3", "p4"])
    directional: Any = field(default_factory=lambda: ["d1", "d2", "d3", "d4", "d5"])


@dataclass
class DatasetConfig:
    """``dataset.*`` (at least 2 failed episodes of one kind: the rules)."""

    expert_episodes: int = constrained(16, ge=2)
    random_episodes: int = constrained(6, ge=0)
    failed_expert_episodes: int = constrained(6, ge=0)
    expert_noise: float = constrained(0.1, ge=0)
    expert_steps_after_success: int | None = constrained(5, ge=0)
    failure_noise: float = constrained(2.0, gt=0)
    max_attempts: int = constrained(10, ge=1)
    held_out_fraction: float = constrained(0.33, gt=0, lt=1)
    cache_dir: str | None = "runs/reward_quality/cache"


@dataclass
class FinetuneConfig:
    """``finetune.*``."""

    updates: int = constrained(1000, ge=0)
    stage: int = constrained(2, choices=(1, 2))


@dataclass
class RewardQualityConfig:
    """The whole config of ``recipes/evaluate_rewards.py`` (``hydra.*`` is Hydra's own)."""

    env: RewardQualityEnvConfig = field(default_factory=RewardQualityEnvConfig)
    encoder: RewardQualityEncoderConfig = field(default_factory=RewardQualityEncoderConfig)
    reward: RewardQualityRewardConfig = field(default_factory=RewardQualityRewardConfig)
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    figures: bool = True
    threads: int | None = constrained(None, ge=1)
    output_dir: str = "runs/reward_quality"
