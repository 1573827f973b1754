"""The schema of ``recipes/sac_temporal.py``'s config: each key's type, default and simple range.

``recipes/config.yaml`` names it first in its defaults list (``recipe_schema``), so Hydra
refuses a value of the wrong type as it composes, naming the key; the ranges declared here with
:func:`~temporal_torchrl.configs.fields.constrained` and the rules that relate keys or need code
(:mod:`temporal_torchrl.configs.rules`) are checked before a run does any work. What each key
means is documented once, in ``config.yaml``'s comments.

The ``Shared*`` classes hold the keys ``recipes/evaluate_rewards.py`` shares with the training
recipe (:mod:`temporal_torchrl.configs.reward_quality`), so both state them once.

The ``reward.*`` defaults restate :mod:`temporal_torchrl.rewards.defaults` rather than import
it: ``temporal_torchrl.configs`` registers the schemas without importing torch (a config is
composed and checked in a fraction of a second), and ``temporal_torchrl.rewards`` imports torch.
``tests/test_rewards.py`` holds the two equal, and ``tests/test_configs.py`` the schema and
``config.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl.configs.fields import constrained

#: ``replay_buffer.embedding_dtype``: the torch dtypes the buffer may store embeddings in.
EMBEDDING_DTYPES = ("float16", "bfloat16", "float32")
#: ``compile.mode``: torch.compile's modes (null: its default).
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")
LOGGER_BACKENDS = ("wandb", "csv", "none")
#: ``reward.projection``: onto the goal from the origin (the thesis's release) or along the
#: baseline-goal line (VLM-RMs).
PROJECTIONS = ("origin", "line")


@dataclass
class SharedEnvConfig:
    """``env.*`` keys of both recipes: the task, its layout and its rendered frames."""

    task: str = "drawer-open"
    seed: int = constrained(0, ge=0)
    max_episode_steps: int = constrained(500, ge=1)
    image_size: int = constrained(64, ge=1)
    camera: str = "corner2"
    fast_render: bool = True


@dataclass
class EnvConfig(SharedEnvConfig):
    """``env.*``."""

    num_envs: int = constrained(1, ge=1)


@dataclass
class EncoderConfig:
    """``encoder.*``; ``options`` is free: ``+encoder.options.<key>=<value>`` adds a key."""

    name: str = "metaworld_small"
    checkpoint: str | None = None
    device: str = "auto"
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class SharedRewardConfig:
    """``reward.*`` keys of both recipes: the reward's parts, its heads and their losses."""

    positional: str | None = "furl"
    directional: str | None = "d3"
    modules: list[str] = field(default_factory=list)
    k: int = constrained(5, ge=1)
    alpha: float = constrained(0.4, ge=0, le=1)
    baseline: str = "generic"
    projection: str = constrained("origin", choices=PROJECTIONS)
    delta: float = constrained(0.1, ge=0)
    l2_margin: float = constrained(0.2, ge=0)
    gap: int = constrained(10, ge=1)
    same_position: bool = True
    batch_size: int = constrained(256, ge=1)
    lr: float = constrained(1.0e-4, gt=0)
    label_window: int | None = constrained(20000, ge=1)
    window: int = constrained(8, ge=2)
    certainty_bandwidth: float = constrained(0.1, gt=0)
    certainty_prior: float = constrained(1.0, gt=0)


@dataclass
class RewardConfig(SharedRewardConfig):
    """``reward.*``."""

    rho: float = constrained(1.0, ge=0)
    lambda_: float = constrained(4.0, ge=0)
    certainty_scaling: bool = False


@dataclass
class SACConfig:
    """``sac.*``."""

    batch_size: int = constrained(256, ge=1)
    lr: float = constrained(1.0e-4, gt=0)
    gamma: float = constrained(0.99, gt=0, le=1)
    tau: float = constrained(0.01, gt=0, le=1)
    alpha_init: float = constrained(1.0, gt=0)
    target_entropy: float | None = None
    hidden_sizes: list[int] = constrained([256, 256], ge=1, nonempty=True)


@dataclass
class ReplayBufferConfig:
    """``replay_buffer.*`` (``capacity`` against the episode length: the rules)."""

    capacity: int | None = None
    embedding_dtype: str = constrained("float16", choices=EMBEDDING_DTYPES)
    device: str = "cpu"


@dataclass
class TrainConfig:
    """``train.*``."""

    episodes: int = constrained(5, ge=1)
    preload_positives: int = constrained(0, ge=0)
    expert_steps_after_success: int | None = constrained(None, ge=0)
    save_positives: bool = False
    positives_from: str | None = None
    relay: bool = True
    relay_periods: list[int] = constrained([50, 100, 150, 200], ge=1, nonempty=True)
    relay_noise: float = constrained(0.2, ge=0)
    relay_threshold: int = constrained(2500, ge=0)
    random_steps: int = constrained(1000, ge=0)
    utd_ratio: float = constrained(1.0, ge=0)
    reward_updates_per_step: float = constrained(1.0, ge=0)
    device: str = "auto"
    checkpoint_every: int = constrained(1, ge=1)
    stop_after_episodes: int | None = constrained(None, ge=1)
    progress: bool = True
    threads: int | None = constrained(None, ge=1)


@dataclass
class CompileConfig:
    """``compile.*`` (``cudagraphs`` needs a CUDA ``train.device``: the rules)."""

    enabled: bool = False
    mode: str | None = constrained(None, choices=COMPILE_MODES)
    cudagraphs: bool = False


@dataclass
class LoggerConfig:
    """``logger.*``."""

    backend: str = constrained("csv", choices=LOGGER_BACKENDS)
    project: str = "temporal-torchrl"
    mode: str = "offline"
    exp_name: str | None = None
    log_every: int = constrained(1000, ge=1)


@dataclass
class RecipeConfig:
    """The whole config of ``recipes/sac_temporal.py`` (``hydra.*`` is Hydra's own)."""

    env: EnvConfig = field(default_factory=EnvConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    replay_buffer: ReplayBufferConfig = field(default_factory=ReplayBufferConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    compile: CompileConfig = field(default_factory=CompileConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    output_dir: str | None = None
    runs_dir: str | None = None
    resume: bool = False
    overwrite: bool = False
