"""The ``make_*`` factories of ``recipes/sac_temporal.py`` (as in TorchRL's sota recipes), from
its config and its :class:`~temporal_torchrl.configs.rules.Devices`, resolved once by the
recipe's build: every part is placed where the others expect it.

They live in the package, not beside the script, so a job that unpickles the recipe elsewhere
(a submitit job on a Slurm node) imports them as any other module.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict
from tensordict.nn import CudaGraphModule, TensorDictModule, TensorDictModuleBase
from tensordict.nn.distributions import NormalParamExtractor
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal
from torchrl.record.loggers import CSVLogger, Logger, WandbLogger

from temporal_torchrl import defaults
from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.data import (
    EpisodeReplayBuffer,
    embed_episode,
    episode_rows,
    goal_image_embedding,
    goal_image_from_rows,
)
from temporal_torchrl.encoders import Encoder, load_encoder
from temporal_torchrl.envs import collect_successful_experts, make_temporal_env
from temporal_torchrl.envs.task_reward import task_text_embeddings
from temporal_torchrl.modules import ReLU
from temporal_torchrl.objectives import StackedCriticSACLoss, StackedQValueNetwork
from temporal_torchrl.params import EnvParams, RelayParams
from temporal_torchrl.rewards import TemporalReward, reward_from_config
from temporal_torchrl.runs import RunDirectory, check_positives_source
from temporal_torchrl.runs.layout import LOGS_DIR
from temporal_torchrl.training.evaluation import PolicyEvaluation
from temporal_torchrl.training.logger import RunLogger
from temporal_torchrl.training.relay import (
    NoRelay,
    RelayExploration,
    RelayPolicy,
    RelaySchedule,
)
from temporal_torchrl.training.trainer import RewardHeadTrainer

#: Added to env.seed for the relay agent's initial weights.
RELAY_SEED_OFFSET = 10_007


def make_encoder(cfg: DictConfig, device: torch.device) -> Encoder:
    """``encoder.*``'s encoder on ``device`` (a training run's ``Devices.encoder``; both recipes
    build their encoder here, and the reward-quality one has no ``train.device``)."""
    options = OmegaConf.to_container(cfg.encoder.options, resolve=True) or {}
    return load_encoder(cfg.encoder.name, checkpoint=cfg.encoder.checkpoint, device=device,
                        **options)


def describe_encoder(cfg: DictConfig, encoder: Encoder | None) -> str:
    """One line naming the encoder a run uses and where its weights came from."""
    if encoder is None:
        return "encoder: none (no VLM reward)"
    weights = {"metaworld_small": "shipped with the package",
               "liv": "Hugging Face Hub jasonyma/LIV (cached)",
               "state": "none (a fixed random projection, not a VLM)"}.get(
        cfg.encoder.name, "open_clip's pretrained tag")
    if cfg.encoder.checkpoint:
        weights = str(cfg.encoder.checkpoint)
    return f"encoder: {encoder.name}, {encoder.dim}-d, weights: {weights}"


def make_reward(cfg: DictConfig, encoder: Encoder, devices: Devices) -> TemporalReward:
    """The run's reward on the train device, goal and baseline texts embedded by the encoder's
    text side."""
    reward = reward_from_config(
        cfg, *task_text_embeddings(cfg.env.task, encoder, cfg.reward.baseline))
    if cfg.compile.enabled:  # the relabelling (and the env's reward) runs compiled
        reward.compile(mode=cfg.compile.mode)
    return reward.to(devices.train)


def make_environment(cfg: DictConfig, encoder: Encoder | None,
                     reward: TemporalReward | None) -> EnvBase:
    return make_temporal_env(EnvParams.from_section(cfg.env), encoder=encoder, reward=reward,
                             num_envs=cfg.env.num_envs)


def make_expert_episodes(cfg: DictConfig, encoder: Encoder | None,
                         count: int) -> list[TensorDict]:
    """``count`` successful scripted-expert episodes with the run's task, layout (random goals:
    layouts of their own) and frames, embedded by ``encoder`` (given the protocol's full 500
    steps to succeed)."""
    env = EnvParams.from_section(cfg.env)
    experts = collect_successful_experts(
        env.replace(max_episode_steps=max(env.max_episode_steps, defaults.MAX_EPISODE_STEPS)),
        count, render=encoder is not None and encoder.input_key == "pixels",
        steps_after_success=cfg.train.expert_steps_after_success)
    return [embed_episode(episode, encoder) if encoder is not None else episode
            for episode in experts]


def make_preloaded_positives(cfg: DictConfig, encoder: Encoder | None, finetune: bool
                             ) -> tuple[list[TensorDict], torch.Tensor | None]:
    """Stage 2's preloaded positives as stored rows, and the goal image s_g (None without
    finetuned heads).

    ``train.preload_positives`` episodes: the first ones another run saved
    (``train.positives_from``, the release's route), or scripted-expert episodes of the run's
    layout and frames, whole unless ``train.expert_steps_after_success`` cuts them. s_g is the
    first success state of the first of them (stage 1: of one scripted expert). With random
    goals, s_g is that of the first expert's layout, one image for every layout, as FuRL's code
    takes its goal image from one oracle episode (``experiments/train_furl.py``).
    """
    dtype = getattr(torch, cfg.replay_buffer.embedding_dtype)
    count = cfg.train.preload_positives
    if cfg.train.positives_from is not None and count > 0:
        rows = saved_positives(cfg, count)
        goal = goal_image_from_rows(rows[0]) if finetune else None
        if encoder is None:  # SAC without a VLM reward stores no embeddings
            return [episode.exclude("embedding") for episode in rows], goal
        for episode in rows:
            episode["embedding"] = episode["embedding"].to(dtype)
        return rows, goal
    if count == 0 and not finetune:
        return [], None
    experts = make_expert_episodes(cfg, encoder, max(count, 1))
    goal = goal_image_embedding(experts[0]) if finetune else None
    return [episode_rows(expert, embedding_dtype=dtype) for expert in experts[:count]], goal


def saved_positives(cfg: DictConfig, count: int) -> list[TensorDict]:
    """The first ``count`` positives the run in ``train.positives_from`` saved
    (``train.save_positives``), checked to come from this run's task, layout, frames and
    encoder."""
    source = RunDirectory(cfg.train.positives_from)
    if not (source.path / "config.json").is_file():
        raise FileNotFoundError(
            f"config train.positives_from={str(source.path)!r}: no run directory there (no "
            "config.json). Pass the output_dir of a run trained with train.save_positives=true.")
    check_positives_source(cfg, source.config())
    saved = source.saved_positive_count()
    if saved < count:
        raise ValueError(
            f"config train.positives_from={str(source.path)!r} holds {saved} saved positive "
            f"episodes, fewer than train.preload_positives={count}: train the source run longer "
            "(resume=true train.episodes=<more>) or preload fewer.")
    return list(source.positive_episodes(count))


def describe_relay(relay: RelayExploration | NoRelay) -> str:
    """One line: whether relay exploration runs, and until when."""
    if isinstance(relay, NoRelay):
        return f"off ({relay.reason})"
    if not relay.schedule.active:
        return f"off (the positives already reach train.relay_threshold={relay.schedule.threshold})"
    params = relay.schedule.params
    return (f"on until {params.threshold:,} positive states (periods {params.periods}, noise "
            f"{params.noise})")


def make_relay(cfg: DictConfig, env: EnvBase, actor: ProbabilisticActor, positive_states: int,
               finetune: bool, devices: Devices) -> RelayExploration | NoRelay:
    """FuRL's relay exploration (``train.relay*``): a second SAC agent on the sparse task reward,
    built from its own seed so the run's other random streams are those of a run without relay;
    off from the start when ``positive_states`` already meet ``train.relay_threshold``.
    :class:`NoRelay` with ``train.relay=false`` or without finetuned heads (``finetune``)."""
    if not cfg.train.relay:
        return NoRelay(actor, "train.relay=false")
    if not finetune:
        return NoRelay(actor, "no finetuned reward heads to relay for")
    params = RelayParams(periods=list(cfg.train.relay_periods), noise=cfg.train.relay_noise,
                         threshold=cfg.train.relay_threshold)
    schedule = RelaySchedule(cfg.env.num_envs, params, seed=cfg.env.seed,
                             active=positive_states < params.threshold)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.env.seed + RELAY_SEED_OFFSET)
        relay_actor, relay_critics = make_sac_agent(cfg, env, devices)
        loss, optimizer = make_sac_loss(cfg, relay_actor, relay_critics,
                                        env.action_spec.shape[-1])
    policy = RelayPolicy(actor, relay_actor, schedule,
                         env.action_spec_unbatched.to(devices.train))
    return RelayExploration(policy, loss, optimizer,
                            make_sac_update(cfg, loss, optimizer))


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


def make_replay_buffer(cfg: DictConfig, capacity: int, reward: TemporalReward | None,
                       devices: Devices) -> EpisodeReplayBuffer:
    """Whole episodes on the replay device; ``sample()`` gives SAC batches on the train device
    relabelled by ``reward``'s current heads, ``finetuning.sample()`` the heads'
    batches; the preloaded experts are permanent. k and the window come from ``reward``, as
    the env's history transform takes them (``reward.k`` without a reward)."""
    return EpisodeReplayBuffer(
        capacity, k=cfg.reward.k if reward is None else None,
        label_window=cfg.reward.label_window, gap=cfg.reward.gap,
        permanent_episodes=cfg.train.preload_positives, reward=reward,
        batch_size=cfg.sac.batch_size, finetuning_batch_size=cfg.reward.batch_size,
        device=devices.replay, batch_device=devices.train)


def make_reward_trainer(cfg: DictConfig, reward: TemporalReward, goal_image: torch.Tensor,
                        buffer: EpisodeReplayBuffer) -> RewardHeadTrainer:
    return RewardHeadTrainer(reward, goal_image, buffer.finetuning,
                             batch_size=cfg.reward.batch_size, lr=cfg.reward.lr,
                             delta=cfg.reward.delta, l2_margin=cfg.reward.l2_margin,
                             same_position=cfg.reward.same_position,
                             compile=cfg.compile.enabled, compile_mode=cfg.compile.mode)


def make_sac_agent(cfg: DictConfig, env: EnvBase,
                   devices: Devices) -> tuple[ProbabilisticActor, StackedQValueNetwork]:
    """Tanh-Gaussian actor and twin Q-networks (stacked) on the train device, MLPs on the state
    (the prior work's SAC)."""
    device = devices.train
    action_spec = env.action_spec_unbatched.to(device)
    action_dim = action_spec.shape[-1]
    actor_net = nn.Sequential(
        MLP(num_cells=list(cfg.sac.hidden_sizes), out_features=2 * action_dim,
            activation_class=ReLU),
        NormalParamExtractor(scale_mapping="biased_softplus_1.0", scale_lb=1e-4))
    actor = ProbabilisticActor(
        TensorDictModule(actor_net, in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"], spec=action_spec, distribution_class=TanhNormal,
        distribution_kwargs={"low": action_spec.space.low, "high": action_spec.space.high,
                             "tanh_loc": False},
        return_log_prob=False)
    with torch.no_grad():  # materialise the lazy layers
        probe = env.fake_tensordict().to(device)
        actor(probe)
    critics = StackedQValueNetwork(2, probe["observation"].shape[-1] + action_dim,
                                   list(cfg.sac.hidden_sizes))
    return actor.to(device), critics.to(device)


def make_sac_loss(cfg: DictConfig, actor: ProbabilisticActor, critics: StackedQValueNetwork,
                  action_dim: int) -> tuple[StackedCriticSACLoss, torch.optim.Optimizer]:
    """SAC's losses (``StackedCriticSACLoss``: TorchRL's ``SACLoss`` with the critics stacked
    rather than vmapped) and one fused Adam over the actor, the critics and the temperature."""
    target_entropy = (-action_dim / 2 if cfg.sac.target_entropy is None
                      else float(cfg.sac.target_entropy))
    loss = StackedCriticSACLoss(actor, critics, gamma=cfg.sac.gamma, tau=cfg.sac.tau,
                                alpha_init=cfg.sac.alpha_init, target_entropy=target_entropy)
    # Fused Adam: the same update as the per-tensor loop, about 7x faster for these MLPs on CPU;
    # captured in a CUDA graph, its state must live on the GPU (capturable).
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg.sac.lr, fused=True,
                                 capturable=cfg.compile.cudagraphs)
    return loss, optimizer


def compile_options(mode: str | None) -> dict:
    """``torch.compile`` options for ``compile.mode`` (its mode's inductor options), with random
    numbers drawn by ATen's generator (``fallback_random``): the compiled SAC update and policy
    take the draws the eager ones take, so a seeded run's episodes do not depend on
    ``compile.enabled`` beyond float rounding."""
    # torch.compile takes a mode or options, not both, and has no public API that gives a
    # mode's options to add ours to.
    return {**torch._inductor.list_mode_options(mode or "default"), "fallback_random": True}


def make_sac_update(cfg: DictConfig, loss: StackedCriticSACLoss,
                    optimizer: torch.optim.Optimizer) -> Callable[[TensorDict], TensorDict]:
    """One SAC step on a batch: losses, backward, Adam, target critics' Polyak step; returns the
    detached losses, alpha and entropy. Compiled with ``compile.enabled`` as in TorchRL's SAC
    recipe (:func:`compile_options`); ``compile.cudagraphs`` also captures it in a CUDA graph."""
    def update(batch: TensorDict) -> TensorDict:
        loss_td = loss(batch)
        (loss_td["loss_actor"] + loss_td["loss_qvalue"] + loss_td["loss_alpha"]).backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        loss.update_target_critics()
        return loss_td.detach()

    if cfg.compile.enabled:
        update = torch.compile(update, options=compile_options(cfg.compile.mode))
    if cfg.compile.cudagraphs:
        update = CudaGraphModule(update, in_keys=[], out_keys=[], warmup=5)
    return update


def make_collector(cfg: DictConfig, env: EnvBase, actor: TensorDictModuleBase,
                   random_frames: int, devices: Devices) -> Collector:
    """One vector step (``env.num_envs`` env steps) per iteration, so every step is followed by
    its updates (the thesis's schedule); uniform random actions for the first ``random_frames``
    steps, then the actor's samples (on the train device, compiled with ``compile.enabled``).
    The collector resets each env when its episode ends."""
    num_envs = cfg.env.num_envs
    return Collector(env, actor, frames_per_batch=num_envs, total_frames=-1,
                     init_random_frames=-(-random_frames // num_envs) * num_envs,
                     exploration_type=ExplorationType.RANDOM,
                     policy_device=devices.train, env_device=env.device,
                     storing_device=env.device,
                     compile_policy=({"options": compile_options(cfg.compile.mode)}
                                     if cfg.compile.enabled else None),
                     auto_register_policy_transforms=False)


def make_evaluation(cfg: DictConfig, devices: Devices) -> PolicyEvaluation | None:
    """The evaluation episodes ``eval.*`` asks for (None with ``eval.every=null``), on the
    run's task, goal setting and episode length, the policy on the train device."""
    if cfg.eval.every is None:
        return None
    return PolicyEvaluation(EnvParams.from_section(cfg.env), cfg.eval.episodes,
                            device=devices.train)


def make_logger(cfg: DictConfig, run_dir: Path) -> RunLogger:
    """The run's ``metrics.jsonl`` and, beside it, the TorchRL logger ``logger.backend`` names
    (CSVLogger in ``logs/``, WandbLogger in ``wandb/``, or none)."""
    return RunLogger(RunDirectory(run_dir), _backend_logger(cfg, run_dir))


def _backend_logger(cfg: DictConfig, run_dir: Path) -> Logger | None:
    name = cfg.logger.exp_name or run_dir.name
    if cfg.logger.backend == "csv":
        return CSVLogger(name, log_dir=str(run_dir / LOGS_DIR))
    if cfg.logger.backend == "wandb":
        return WandbLogger(name, offline=cfg.logger.mode != "online", save_dir=str(run_dir),
                           project=cfg.logger.project,
                           config=OmegaConf.to_container(cfg, resolve=True))
    return None
