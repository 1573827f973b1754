"""The config of ``recipes/sac_temporal.py``: every key's type, default, range and meaning.

This module is the one home of the recipe's settings. ``recipes/config.yaml`` holds only the
defaults list (this schema, ``recipe_schema``, first; then the preset and the protocol) and
Hydra's own settings; the presets and protocols (``recipes/preset``, ``recipes/protocol``) state
only what they change. Hydra refuses a value of the wrong type as it composes, naming the key;
the ranges declared here with :func:`~temporal_torchrl.fields.constrained` and the rules
that relate keys or need code (:mod:`temporal_torchrl.configs.rules`) are checked before a run
does any work. ``python recipes/sac_temporal.py --cfg job`` prints the composed config.

The components' parameter objects (:mod:`temporal_torchrl.params`) are nested as they are: ``env``
is :class:`~temporal_torchrl.params.EnvParams` (with ``num_envs``), ``eval``
:class:`~temporal_torchrl.params.EvalParams`, and ``train.relay_*`` take their defaults and
ranges from :class:`~temporal_torchrl.params.RelayParams`'s fields; the recipe hands them to the
library's constructors as these objects. The reward's defaults are read from
:mod:`temporal_torchrl.defaults`.

The default run is the whole pipeline offline on a CPU (time and output: README.md): rendering
at 64x64, the package's own small vision-language encoder (``metaworld_small``, trained with
LIV's objective; its weights ship in the package), the thesis's best reward (FuRL ρ 1.0 + D3 λ
4.0, generic baseline) and 5 episodes of 500 steps, 1,000 of them random. The thesis presets
switch to the LIV encoder at 256x256, 1,000 episodes and 10,000 random steps.

``recipes/evaluate_rewards.py`` shares ``env.*`` (:class:`~temporal_torchrl.params.EnvParams`)
and the ``reward.*`` keys of :class:`SharedRewardConfig` with the training recipe
(:mod:`temporal_torchrl.configs.reward_quality`), so both state them once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl import defaults
from temporal_torchrl.fields import constrained, field_of
from temporal_torchrl.params import EnvParams, EvalParams, RelayParams

#: ``replay_buffer.embedding_dtype``: the torch dtypes the buffer may store embeddings in.
EMBEDDING_DTYPES = ("float16", "bfloat16", "float32")
#: ``compile.mode``: torch.compile's modes (null: its default).
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")
#: ``logger.backend``: where the training metrics go besides ``metrics.jsonl``.
LOGGER_BACKENDS = ("wandb", "csv", "none")


@dataclass
class EnvConfig(EnvParams):
    """``env.*``: :class:`~temporal_torchrl.params.EnvParams` and the copies stepped."""

    #: Copies of the task stepped in parallel worker processes (the thesis: 1).
    num_envs: int = constrained(1, ge=1)


@dataclass
class EncoderConfig:
    """``encoder.*``: the frozen vision-language model."""

    #: One of :data:`~temporal_torchrl.encoders.ENCODERS`; ``state`` is a random projection of
    #: the state vector, no rendering and NOT a vision-language model: for checking the
    #: algorithm fast.
    name: str = "metaworld_small"
    #: A local weights file (liv: LIV's ``model.pt``); null downloads LIV.
    checkpoint: str | None = None
    #: auto (cuda when available, else cpu) | cpu | cuda:0 ...
    device: str = "auto"
    #: Passed to ``load_encoder``; add keys with ``+``: ``+encoder.options.dim=64`` (state),
    #: ``+encoder.options.model_name=RN50-quickgelu`` (open_clip).
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
    #: The parts' options, each added with ``+``: ``+reward.options.<name>=<value>``; an
    #: option not given keeps its registered default. d_sequence: ``window``, K, the embeddings
    #: s_(t-K+1) .. s_t its sequence encoder reads; d_certainty (and ``certainty_scaling``):
    #: ``certainty_bandwidth``, the kernel width beta in median distances, and
    #: ``certainty_prior``, the pseudo-count c (little evidence: a target near 0); your own:
    #: those ``register_reward(..., options=...)`` declares.
    options: dict[str, Any] = field(default_factory=dict)
    #: k, the history offset of s_{t-k}.
    k: int = constrained(defaults.K, ge=1)
    #: alpha, the goal-baseline regularisation of P3, P4 and D5.
    alpha: float = constrained(defaults.ALPHA, ge=0, le=1)
    #: The baseline text b: generic | tailored | any text.
    baseline: str = defaults.BASELINE
    #: origin (the thesis's release) | line (VLM-RMs).
    projection: str = constrained(defaults.PROJECTION, choices=defaults.PROJECTIONS)
    #: delta, the ranking margin of the positional loss.
    delta: float = constrained(defaults.DELTA, ge=0)
    #: The finetuning stage-1 goal-distance margin.
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
    #: Deprecated (one more release): ``reward.options.window``, which it is read as (null:
    #: not set; so is its old default, 8, which every saved run's config.json holds).
    window: int | None = constrained(None, ge=2)
    #: Deprecated (one more release): ``reward.options.certainty_bandwidth`` (null, or 0.1:
    #: not set).
    certainty_bandwidth: float | None = constrained(None, gt=0)
    #: Deprecated (one more release): ``reward.options.certainty_prior`` (null, or 1.0: not
    #: set).
    certainty_prior: float | None = constrained(None, gt=0)


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
    """``sac.*``: the agent and its update."""

    #: Transitions per SAC update.
    batch_size: int = constrained(256, ge=1)
    #: Adam's learning rate of the actor, the critics and the temperature.
    lr: float = constrained(1.0e-4, gt=0)
    #: The discount.
    gamma: float = constrained(0.99, gt=0, le=1)
    #: The target critics' soft update, every step.
    tau: float = constrained(0.01, gt=0, le=1)
    #: The initial temperature (1.0: log alpha = 0).
    alpha_init: float = constrained(1.0, gt=0)
    #: null: -action_dim / 2 (= -2).
    target_entropy: float | None = None
    #: The actor's and each critic's hidden layers.
    hidden_sizes: list[int] = constrained([256, 256], ge=1, nonempty=True)


@dataclass
class ReplayBufferConfig:
    """``replay_buffer.*`` (``capacity`` against the episode length: the rules)."""

    #: Rows; null: enough for the whole run (capped at 1,000,000).
    capacity: int | None = None
    #: The dtype the embeddings are stored in (never pixels).
    embedding_dtype: str = constrained("float16", choices=EMBEDDING_DTYPES)
    #: Where the storage lives: cpu (batches go to train.device through pinned memory) | auto
    #: (train.device) | any torch device.
    device: str = "cpu"


@dataclass
class TrainConfig:
    """``train.*``: the loop."""

    #: Training episodes (the default run: README.md; the thesis: 1,000).
    episodes: int = constrained(5, ge=1)
    #: Expert episodes inserted as positives before training (protocol stage 2: 50).
    preload_positives: int = constrained(0, ge=0)
    #: null: experts kept whole (500 steps), as the thesis release preloads its positives; n: cut
    #: n steps after the first success.
    expert_steps_after_success: int | None = constrained(None, ge=0)
    #: Save every successful training episode, whole, in ``<run>/positives/``.
    save_positives: bool = False
    #: Preload the first ``preload_positives`` positives another run saved (the thesis release's
    #: protocol stage 2: a stage-1 run with save_positives=true); null: scripted-expert episodes
    #: of this run's layout.
    positives_from: str | None = None
    #: FuRL's relay exploration (the release keeps it on): episodes alternate between this agent
    #: and a SAC agent on the sparse reward until the finetuning holds relay_threshold positive
    #: states; needs finetuned heads.
    relay: bool = True
    #: Switch agents every period steps, one period drawn per episode.
    relay_periods: list[int] = field_of(RelayParams, "periods")
    #: Gaussian noise on the relay agent's actions, times the action bound.
    relay_noise: float = field_of(RelayParams, "noise")
    #: Positive states that end relay (protocol stage 2's 50 preloaded: it never starts).
    relay_threshold: int = field_of(RelayParams, "threshold")
    #: Uniform random actions first (the thesis: 10,000).
    random_steps: int = constrained(1000, ge=0)
    #: SAC updates per env step after the warm-up, at any env.num_envs (the thesis: 1);
    #: fractions are carried over (0.5: one update every 2 steps).
    utd_ratio: float = constrained(1.0, ge=0)
    #: Reward-head updates per env step, likewise.
    reward_updates_per_step: float = constrained(1.0, ge=0)
    #: Actor, critics, heads, losses, relabelling, batches: auto (cuda when available, else
    #: cpu) | cpu | cuda:0 ...
    device: str = "auto"
    #: Episodes between checkpoints; 1 loses at most the episode in progress when killed.
    checkpoint_every: int = constrained(1, ge=1)
    #: End the process after this many episodes, as if killed (tests).
    stop_after_episodes: int | None = constrained(None, ge=1)
    #: The tqdm progress bar.
    progress: bool = True
    #: Torch CPU threads for this run (null: torch's default).
    threads: int | None = constrained(None, ge=1)


@dataclass
class CompileConfig:
    """``compile.*``, as TorchRL's SAC recipe (``cudagraphs`` needs a CUDA ``train.device``:
    the rules)."""

    #: torch.compile the SAC update, the reward-head losses, the relabelling reward and the
    #: policy (the CPU studies: true).
    enabled: bool = False
    #: torch.compile's mode: null (its default) or one of :data:`COMPILE_MODES`.
    mode: str | None = constrained(None, choices=COMPILE_MODES)
    #: CUDA only: capture the SAC update in a CUDA graph (CudaGraphModule).
    cudagraphs: bool = False


@dataclass
class LoggerConfig:
    """``logger.*`` (``metrics.jsonl`` is written whatever the backend)."""

    #: One of :data:`LOGGER_BACKENDS`.
    backend: str = constrained("csv", choices=LOGGER_BACKENDS)
    #: The wandb project.
    project: str = "temporal-torchrl"
    #: wandb: offline unless online.
    mode: str = "offline"
    #: The experiment's name (null: the run directory's).
    exp_name: str | None = None
    #: SAC updates between logged training metrics (means over them): SAC's losses, alpha,
    #: entropy; each finetuning loss term; the finetuning stage; the number of positive states;
    #: mean/std of the relabelled r_P and r_D; the seconds per phase of the loop.
    log_every: int = constrained(1000, ge=1)


@dataclass
class RecipeConfig:
    """The whole config of ``recipes/sac_temporal.py``; ``config.yaml``'s defaults list adds a
    ``preset`` and a ``protocol`` (``recipes/preset``, ``recipes/protocol``) and Hydra's own
    ``hydra.*``."""

    env: EnvConfig = field(default_factory=EnvConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    replay_buffer: ReplayBufferConfig = field(default_factory=ReplayBufferConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    eval: EvalParams = field(default_factory=EvalParams)
    compile: CompileConfig = field(default_factory=CompileConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    #: The run directory; null:
    #: ``<runs_dir>/<task>/<encoder>_<pos>+<dir>_rho<r>_lambda<l>_<baseline>_<protocol>/seed<s>``
    #: (``runs.default_run_dir``).
    output_dir: str | None = None
    #: The root of the default run directories; null: ``runs/``, or in a ``-m`` sweep the sweep
    #: directory (hydra.sweep.dir).
    runs_dir: str | None = None
    #: Continue the run in output_dir from its last checkpoint.
    resume: bool = False
    #: Delete an existing output_dir and start over.
    overwrite: bool = False
