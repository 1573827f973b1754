"""The schema of ``recipes/sac_temporal.py``'s config: each key's type, default and simple range.

``recipes/config.yaml`` names it first in its defaults list (``recipe_schema``), so Hydra
refuses a value of the wrong type as it composes, naming the key; the ranges declared here with
:func:`~temporal_torchrl.configs.fields.constrained` and the rules that relate keys or need code
(:mod:`temporal_torchrl.configs.rules`) are checked before a run does any work. The
``reward.*`` keys are documented here, beside their defaults, which are the library's own
(:mod:`temporal_torchrl.defaults`, read from there: the YAML files do not restate them); the other
keys in ``config.yaml``'s comments.

The ``Shared*`` classes hold the keys ``recipes/evaluate_rewards.py`` shares with the training
recipe (:mod:`temporal_torchrl.configs.reward_quality`), so both state them once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl import defaults
from temporal_torchrl.configs.fields import constrained

#: ``replay_buffer.embedding_dtype``: the torch dtypes the buffer may store embeddings in.
EMBEDDING_DTYPES = ("float16", "bfloat16", "float32")
#: ``compile.mode``: torch.compile's modes (null: its default).
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")
LOGGER_BACKENDS = ("wandb", "csv", "none")


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
    #: fixed: one layout per run, from env.seed (the thesis) | random: a new layout at every
    #: reset, from a stream seeded by env.seed (the goal then observable).
    goal: str = constrained(defaults.GOAL, choices=defaults.GOALS)


@dataclass
class EvalConfig:
    """``eval.*``: evaluation episodes of the deterministic policy, apart from training (none in
    the thesis's protocol)."""

    #: Evaluate after every this many training episodes (null: never).
    every: int | None = constrained(None, ge=1)
    #: Episodes per evaluation: random goals, each on its own held-out layout (the same ones at
    #: every evaluation); fixed goals, on the run's layout.
    episodes: int = constrained(defaults.EVAL_EPISODES, ge=1)


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

    #: r_P: none | liv | furl | p1 | p2 | p3 | p4 | one registered by ``reward.modules``.
    positional: str | None = defaults.POSITIONAL_REWARD
    #: r_D: none | d1 ... d5 | d_certainty | d_sequence (beyond the thesis) | one registered.
    directional: str | None = defaults.DIRECTIONAL_REWARD
    #: .py files or module names imported first, to ``register_reward`` your own.
    modules: list[str] = field(default_factory=list)
    #: The parts' own options (``register_reward(..., options=...)``), each added with ``+``:
    #: ``+reward.options.<name>=<value>``; an option not given keeps its registered default.
    options: dict[str, Any] = field(default_factory=dict)
    #: k, the history offset of s_{t-k}.
    k: int = constrained(defaults.HISTORY, ge=1)
    #: alpha, the goal-baseline regularisation of P3, P4 and D5.
    alpha: float = constrained(defaults.ALPHA, ge=0, le=1)
    #: The baseline text b: generic | tailored | any text.
    baseline: str = defaults.BASELINE
    #: origin (the thesis's release) | line (VLM-RMs).
    projection: str = constrained(defaults.PROJECTION, choices=defaults.PROJECTIONS)
    #: delta, the ranking margin of the positional loss.
    delta: float = constrained(defaults.DELTA, ge=0)
    #: The stage-1 goal-distance margin.
    l2_margin: float = constrained(defaults.L2_MARGIN, ge=0)
    #: The pos-pos lag (and the first steps never drawn as positives).
    gap: int = constrained(defaults.GAP, ge=1)
    #: The directional loss as in the thesis text; false: the release's D4/D5.
    same_position: bool = defaults.SAME_POSITION
    #: States per finetuning batch of each kind.
    batch_size: int = constrained(defaults.HEADS_BATCH_SIZE, ge=1)
    #: The heads' Adam learning rate.
    lr: float = constrained(defaults.HEADS_LEARNING_RATE, gt=0)
    #: Positives and negatives are sampled from the most recent this many of each kind.
    label_window: int | None = constrained(defaults.LABEL_WINDOW, ge=1)
    #: d_sequence: K, the embeddings s_(t-K+1) .. s_t its sequence encoder reads.
    window: int = constrained(defaults.WINDOW_LENGTH, ge=2)
    #: d_certainty's target: the kernel width beta, in median distances.
    certainty_bandwidth: float = constrained(defaults.CERTAINTY_BANDWIDTH, gt=0)
    #: d_certainty's target: the pseudo-count c (little evidence: a target near 0).
    certainty_prior: float = constrained(defaults.CERTAINTY_PRIOR, gt=0)


@dataclass
class RewardConfig(SharedRewardConfig):
    """``reward.*``."""

    #: rho in r = r_task + rho (r_P + lambda r_D).
    rho: float = constrained(defaults.RHO, ge=0)
    #: lambda, the directional weight.
    lambda_: float = constrained(defaults.LAMBDA, ge=0)
    #: r_D times the certainty's magnitude at reward time (the thesis's 6.4 alternative; any
    #: directional reward, e.g. d3).
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
    #: Switch agents every period steps, one period drawn per episode.
    relay_periods: list[int] = constrained(list(defaults.RELAY_PERIODS), ge=1, nonempty=True)
    #: Gaussian noise on the relay agent's actions, times the action bound.
    relay_noise: float = constrained(defaults.RELAY_NOISE, ge=0)
    #: Positive states that end relay (stage 2's 50 preloaded: it never starts).
    relay_threshold: int = constrained(defaults.RELAY_THRESHOLD, ge=0)
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
    eval: EvalConfig = field(default_factory=EvalConfig)
    compile: CompileConfig = field(default_factory=CompileConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    output_dir: str | None = None
    runs_dir: str | None = None
    resume: bool = False
    overwrite: bool = False
