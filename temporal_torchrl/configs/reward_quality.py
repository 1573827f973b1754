"""The config of ``recipes/evaluate_rewards.py``: every key's type, default, range and meaning.

The one home of the offline benchmark's settings: ``recipes/evaluate_rewards.yaml`` holds only
the defaults list and Hydra's own settings. ``env.*``, ``encoder.*`` and ``reward.*`` are the
training recipe's (:mod:`temporal_torchrl.configs.recipe`, with its defaults and meanings), but
for the keys that take several values here: ``env.task`` a task name or a list of them (one
table per task and a summary), ``reward.positional`` and ``reward.directional`` a variant or a
list of variants, every one listed scored (each checked by
:mod:`temporal_torchrl.configs.rules`). ``dataset.*`` nests
:class:`~temporal_torchrl.params.DatasetParams`, which
:class:`~temporal_torchrl.reward_quality.DatasetSpec` holds beside the env's settings.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl.configs.recipe import EncoderConfig, SharedRewardConfig
from temporal_torchrl.fields import constrained
from temporal_torchrl.params import DatasetParams, EnvParams


@dataclass
class RewardQualityEnvConfig(EnvParams):
    """``env.*``: :class:`~temporal_torchrl.params.EnvParams`; ``task`` may be a list of task
    names (one table per task). ``seed`` also draws the held-out split, ``max_episode_steps``
    is the failed episodes' length (the experts get 500 steps to succeed), and ``goal`` is
    ``fixed``: the episodes are scored on the run's layout (the rules refuse ``random``)."""

    #: A Metaworld MT50 short name, or a list of them.
    task: Any = "drawer-open"


@dataclass
class RewardQualityEncoderConfig(EncoderConfig):
    """``encoder.*``, on the CPU unless told otherwise."""

    #: cpu | auto (cuda when available) | cuda:0 ...
    device: str = "cpu"


@dataclass
class RewardQualityRewardConfig(SharedRewardConfig):
    """``reward.*``; every variant listed in ``positional`` and ``directional`` is scored."""

    #: none, or any of POSITIONAL, or a list of them (your own: ``reward.modules``).
    positional: Any = field(default_factory=lambda: ["liv", "furl", "p1", "p2", "p3", "p4"])
    #: none, or any of DIRECTIONAL (also d_certainty and d_sequence: beyond the thesis), or a
    #: list of them.
    directional: Any = field(default_factory=lambda: ["d1", "d2", "d3", "d4", "d5"])


@dataclass
class DatasetConfig(DatasetParams):
    """``dataset.*``: :class:`~temporal_torchrl.params.DatasetParams` (at least 2 failed
    episodes of one kind: the rules), the split and the cache."""

    #: Of each kind's episodes, the fraction held out for scoring.
    held_out_fraction: float = constrained(0.33, gt=0, lt=1)
    #: Where collected episodes are cached; null: collect every time.
    cache_dir: str | None = "runs/reward_quality/cache"


@dataclass
class FinetuneConfig:
    """``finetune.*``: the heads' finetuning before scoring."""

    #: Head updates per configuration (one batch each).
    updates: int = constrained(1000, ge=0)
    #: 2: successful and failed episodes; 1: failed episodes only.
    stage: int = constrained(2, choices=(1, 2))


@dataclass
class RewardQualityConfig:
    """The whole config of ``recipes/evaluate_rewards.py`` (``hydra.*`` is Hydra's own)."""

    env: RewardQualityEnvConfig = field(default_factory=RewardQualityEnvConfig)
    encoder: RewardQualityEncoderConfig = field(default_factory=RewardQualityEncoderConfig)
    reward: RewardQualityRewardConfig = field(default_factory=RewardQualityRewardConfig)
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    #: One PNG per configuration (the reward along a held-out episode of each kind).
    figures: bool = True
    #: Torch CPU threads (null: torch's default).
    threads: int | None = constrained(None, ge=1)
    #: Results in ``<output_dir>/<task>/``, ``summary.md`` for several tasks.
    output_dir: str = "runs/reward_quality"
