"""SAC with temporal VLM reward shaping on Metaworld (thesis chapter 5).

Each env step (a TorchRL collector: uniform random actions during the warm-up, then the actor's
samples; render -> embed -> history -> reward, the reward only logged) is followed by one
reward-head update and one SAC update on batches from the episode replay buffer, whose transform
relabels SAC's rewards from the stored embeddings with the heads as they are now. Each ended
episode is labelled and inserted into the buffer, then an episode row and a checkpoint are
written; every ``eval.every`` episodes the deterministic policy is evaluated apart from training.

    python recipes/sac_temporal.py                                # quick default (offline, CPU)
    python recipes/sac_temporal.py preset=best protocol=stage2 env.task=door-open env.seed=2
    python recipes/sac_temporal.py preset=best protocol=stage2 resume=true  # continue a killed run
    python recipes/sac_temporal.py output_dir=runs/x resume=true train.episodes=2000  # extend it
    python recipes/sac_temporal.py preset=sac env.goal=random eval.every=10  # random goals

Outputs in ``output_dir`` (default: ``runs/<task>/<method>_<protocol>/seed<seed>``, see
:func:`temporal_torchrl.runs.default_run_dir`; layout in
:mod:`temporal_torchrl.runs.directory`): ``episodes.csv`` (episode, env_steps, success, return =
sum of sparse task rewards, mean_vlm_reward, stage), ``eval.csv`` (with ``eval.every``: one row
per evaluation), ``summary.json`` (TTFS, TT50S, RAS, the last and best evaluation, throughput,
the resolved config, the last training metrics, the provenance), ``provenance.json`` (each
start's commit and whether the tree was clean, library versions, CPU, torch threads),
``checkpoint.pt`` + ``replay/`` (resume), ``metrics.jsonl`` (whatever ``logger.backend``:
per-episode rows and, every ``logger.log_every`` updates, SAC's and the heads' losses and the
relabelled reward statistics; what reports read) and the same in ``logs/`` (CSV logger) or
``wandb/``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl import timeit
from torchrl.collectors import Collector
from tqdm import tqdm

from temporal_torchrl.configs.rules import Devices, validate_recipe_config
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.encoders import Encoder
from temporal_torchrl.rewards.config import uses_vlm_reward
from temporal_torchrl.runs import (
    RunDirectory,
    override_keys,
    run_directory,
    sweep_job_config,
)
from temporal_torchrl.runs.provenance import current_provenance
from temporal_torchrl.runs.sweep_job import run_sweep_job
from temporal_torchrl.training import (
    EpisodeAssembler,
    MetricWindow,
    RewardHeadTrainer,
    RunLogger,
    RunStart,
    TrainingState,
    episode_row,
    factories,
    log_metrics,
    reward_statistics,
    run_summary,
    start_run,
)
from temporal_torchrl.training.evaluation import PolicyEvaluation
from temporal_torchrl.training.relay import NoRelay, RelayExploration
from temporal_torchrl.training.timing import PhaseClock, timed

#: Called after each episode the run records, with its number and the run's env steps then.
EpisodeEndHook = Callable[[int, int], None]


def train(cfg: DictConfig, given_keys: Collection[str] | None = None,
          on_episode_end: EpisodeEndHook | None = None) -> dict | None:
    """Run (or resume) one training run; returns its summary, or None when stopped early.

    ``given_keys``: the keys set on the command line, which alone may change a resumed run's
    ``train.episodes`` and ``train.checkpoint_every`` (None: all of ``cfg``'s do).
    ``on_episode_end(episode, env_steps)``: called once each episode is recorded (benchmarks time
    the loop with it). The run directory's lock is held throughout: ``RunLockedError`` at once
    when a live process holds it.
    """
    cfg = validate_recipe_config(cfg)
    run_dir = RunDirectory(run_directory(cfg))
    # One writer per run directory, for the whole run; its config beside the lock lets a
    # sweep job tell another config's run from a relaunch of its own.
    with run_dir.lock(config=OmegaConf.to_container(cfg, resolve=True)):
        return _train(cfg, run_dir, given_keys, on_episode_end or (lambda episode, env_steps: None))


@dataclass
class Training:
    """What a run trains with, built by :func:`build`."""

    encoder: Encoder | None
    buffer: EpisodeReplayBuffer
    trainer: RewardHeadTrainer | None  # None: no finetuned heads
    relay: RelayExploration | NoRelay
    actor: TensorDictModuleBase  # SAC's policy, which the evaluation runs deterministically
    evaluation: PolicyEvaluation | None  # None: no evaluation episodes (eval.every=null)
    update_sac: Callable[[TensorDictBase], TensorDictBase]
    state: TrainingState  # its progress: the counters the loop advances
    collector: Collector
    random_until: int  # the env steps whose actions are uniform random
    logger: RunLogger


def build(start: RunStart, run_dir: RunDirectory) -> Training:
    """The encoder, reward, env, SAC agent, replay, head trainer, relay and collector of the run
    ``start`` begins, its replay filled and, on a resume, its checkpoint restored. The order is
    that of the build's random draws, which a resume must repeat."""
    cfg, saved = start.cfg, start.checkpoint  # saved: None on a fresh start
    devices = Devices.of(cfg)  # each part's device, resolved once for all the factories
    torch.manual_seed(cfg.env.seed)

    # ---- encoder, reward, env
    encoder = factories.make_encoder(cfg, devices.encoder) if uses_vlm_reward(cfg) else None
    reward = factories.make_reward(cfg, encoder, devices) if encoder is not None else None
    env = factories.make_environment(cfg, encoder, reward)
    print(f"run directory: {run_dir.path}")
    if saved is not None:  # a killed run's log shows where it went on from
        print(f"resumed: after episode {saved.episode:,} of {cfg.train.episodes:,} "
              f"({saved.env_steps:,} env steps, {saved.updates:,} SAC updates)")
    print(factories.describe_encoder(cfg, encoder))

    # ---- stage 2's preloaded positives and the goal image s_g (a resume has them saved)
    finetune = reward is not None and (reward.positional_heads is not None
                                       or reward.directional_heads is not None)
    if saved is None:
        preloaded, goal_image = factories.make_preloaded_positives(cfg, encoder, finetune)
        expert_rows = sum(len(rows) for rows in preloaded)
    else:
        preloaded, goal_image, expert_rows = [], saved.goal_image, saved.expert_rows

    # ---- SAC, replay buffer, reward-head trainer
    actor, critics = factories.make_sac_agent(cfg, env, devices)
    sac_loss, sac_optimizer = factories.make_sac_loss(cfg, actor, critics,
                                                      env.action_spec.shape[-1])
    update_sac = factories.make_sac_update(cfg, sac_loss, sac_optimizer)
    buffer = factories.make_replay_buffer(cfg, factories.replay_capacity(
        cfg, expert_rows, saved=saved.buffer_capacity if saved else None), reward, devices)
    trainer = factories.make_reward_trainer(cfg, reward, goal_image, buffer) if finetune else None

    # ---- the replay filled, the relay, then the checkpoint's modules and counters restored
    progress = start.fill_replay(buffer, preloaded)
    relay = factories.make_relay(cfg, env, actor, buffer.num_positive_states, finetune, devices)
    state = TrainingState(progress, sac_loss=sac_loss, sac_optimizer=sac_optimizer,
                          reward=reward, trainer=trainer, relay=relay, goal_image=goal_image,
                          buffer_capacity=buffer.capacity, expert_rows=expert_rows,
                          preloaded=buffer.num_permanent_episodes)
    start.restore(state)
    print(f"relay exploration: {factories.describe_relay(relay)}")
    collector = factories.make_collector(cfg, env, relay.policy,
                                         max(0, cfg.train.random_steps - progress.env_steps),
                                         devices)
    random_until = progress.env_steps + collector.init_random_frames
    evaluation = factories.make_evaluation(cfg, devices)
    start.restore_rng()  # after every random draw the build makes
    return Training(encoder, buffer, trainer, relay, actor, evaluation, update_sac, state,
                    collector, random_until, factories.make_logger(cfg, run_dir.path))


def _train(cfg: DictConfig, run_dir: RunDirectory, given_keys: Collection[str] | None,
           on_episode_end: EpisodeEndHook) -> dict | None:
    """:func:`train`, once the run's lock is held."""
    start = start_run(run_dir, cfg, given_keys)  # afresh, from the checkpoint, or already complete
    if start.complete:
        print(f"{run_dir.path}: already complete ({start.checkpoint.episode} episodes)")
        return start.summary
    cfg, training = start.cfg, build(start, run_dir)
    run_dir.record_start(current_provenance(training.state.progress.episode))  # commit, versions
    buffer, trainer, relay, logger = (training.buffer, training.trainer, training.relay,
                                      training.logger)
    state, progress = training.state, training.state.progress
    metrics = MetricWindow()
    embedding_dtype = getattr(torch, cfg.replay_buffer.embedding_dtype)
    episodes = EpisodeAssembler(cfg.env.num_envs, buffer.stage)

    @timeit("time/logging")
    def log_training_metrics() -> None:
        progress.last_metrics = metrics.flush() | {
            "train/stage": float(buffer.stage), "train/positive_states": buffer.num_positive_states}
        log_metrics(logger, progress.last_metrics | clock.window(), progress.env_steps)

    def update(env_steps: int) -> None:
        """The reward-head and SAC updates ``env_steps`` new env steps are owed."""
        sac_updates, reward_updates = progress.credits.add(
            env_steps, cfg.train.utd_ratio,
            cfg.train.reward_updates_per_step if trainer is not None else 0)
        for _ in range(reward_updates):
            with timeit("time/head_update"):
                metrics.add("reward", trainer.update())
        for _ in range(sac_updates):
            with timeit("time/replay_sample"):
                batch = buffer.sample()  # rewards relabelled with the current heads
            with timeit("time/sac_update"):
                relay_batch = relay.batch_to_learn(batch)  # before SAC's update adds its keys
                metrics.add("sac", training.update_sac(batch))
                if relay_batch is not None:  # the relay agent learns from the same batches
                    metrics.add("relay", relay.update(relay_batch))
            metrics.add("relabelled", reward_statistics(batch["next"]))
            progress.updates += 1
            if progress.updates % cfg.logger.log_every == 0:
                log_training_metrics()

    @timeit("time/evaluation")
    def evaluate() -> None:
        """The deterministic policy on the evaluation layouts, after episode
        ``progress.episode``: a row of ``eval.csv``, logged at the training's env steps."""
        result = training.evaluation(training.actor)
        run_dir.append_evaluation({"episode": progress.episode,
                                   "env_steps": progress.env_steps} | result)
        log_metrics(logger, {f"eval/{key}": float(value) for key, value in result.items()
                             if key != "episodes"}, progress.env_steps)

    @timeit("time/episode_end")
    def finish_episode(index: int) -> None:
        """Env ``index``'s episode ended: labelled and inserted, saved, its row logged."""
        trajectory, ran_in = episodes.pop(index)
        rows = episode_rows(trajectory, embedding_dtype=embedding_dtype)
        buffer.extend(rows)
        run_dir.save_replay_episode(progress.inserted, rows)
        progress.inserted += 1
        progress.episode += 1
        row = episode_row(trajectory, progress.episode, progress.env_steps, ran_in)
        progress.successes.append(bool(row["success"]))
        if row["success"] and cfg.train.save_positives:
            run_dir.save_positive_episode(progress.episode, rows)
        run_dir.append_episode(row)
        logged = {f"train/{key}": float(row[key])
                  for key in ("success", "return", "mean_vlm_reward", "stage")}
        logged |= relay.episode_metrics(index, len(trajectory))
        log_metrics(logger, logged, progress.env_steps)
        episodes.begin(index, buffer.stage)
        on_episode_end(progress.episode, progress.env_steps)

    # ---- training loop: one vector step of env.num_envs envs, then its updates
    num_envs, start_time, start_steps = cfg.env.num_envs, time.perf_counter(), progress.env_steps
    bar = tqdm(total=cfg.train.episodes, initial=progress.episode,
               disable=not cfg.train.progress, desc="episodes")
    clock = PhaseClock()  # seconds per phase (temporal_torchrl/training/timing.py)
    for data in timed(training.collector, "env_step"):
        progress.env_steps += num_envs
        if progress.env_steps > cfg.train.random_steps and buffer.num_transitions > 0:
            update(num_envs)
        ended = episodes.add(data)
        relay.advance(ended, acted=progress.env_steps > training.random_until)
        if not ended:
            continue
        checkpointed_before = progress.episode // cfg.train.checkpoint_every
        for index in ended[:cfg.train.episodes - progress.episode]:  # in env order
            finish_episode(index)
            bar.update(1)
            if training.evaluation is not None and progress.episode % cfg.eval.every == 0:
                evaluate()
        relay.end_if_enough(buffer.num_positive_states)
        steps_per_second = (progress.env_steps - start_steps) / (time.perf_counter() - start_time)
        bar.set_postfix(success_rate=f"{sum(progress.successes) / len(progress.successes):.2f}",
                        steps_per_s=f"{steps_per_second:.0f}")
        done = progress.episode >= cfg.train.episodes
        if progress.episode // cfg.train.checkpoint_every > checkpointed_before or done:
            with timeit("time/checkpoint"):
                run_dir.save_checkpoint(state.checkpoint())
        if done or progress.episode >= (cfg.train.stop_after_episodes or math.inf):
            break
    bar.close()
    training.collector.shutdown()
    if progress.episode < cfg.train.episodes:
        return None  # stopped early, as if killed (train.stop_after_episodes)
    if metrics.pending:  # the last window, shorter than logger.log_every updates
        log_training_metrics()

    summary = run_summary(
        cfg, progress, encoder=cfg.encoder.name if training.encoder is not None else None,
        steps_per_second=(progress.env_steps - start_steps) / (time.perf_counter() - start_time),
        relay_steps=relay.total_steps, phase_seconds=clock.totals(),
        evaluations=run_dir.evaluation_rows(), provenance=run_dir.provenance())
    run_dir.write_summary(summary)
    log_metrics(logger, {f"summary/{key}": float(summary[key]) for key in ("ttfs", "tt50s")},
                progress.env_steps)
    return summary


def run(cfg: DictConfig, given_keys: Collection[str] | None = None) -> None:
    """:func:`train` in this process, with ``train.threads`` torch threads; prints the summary."""
    # Libraries log their progress at INFO (open_clip's model creation, TorchRL's storage); the
    # recipe prints its own lines and a progress bar, which those would interleave with.
    for name in ("", "torchrl"):
        logging.getLogger(name).setLevel(logging.WARNING)
    if cfg.train.threads is not None:
        torch.set_num_threads(cfg.train.threads)
    summary = train(cfg, given_keys)
    if summary is not None:
        print({key: summary[key] for key in ("ttfs", "tt50s", "ras", "episodes", "env_steps",
                                              "steps_per_second")})


@hydra.main(version_base=None, config_path=".", config_name="config")
def main(cfg: DictConfig) -> None:
    hydra_config = HydraConfig.get()
    given_keys = override_keys(hydra_config.overrides.task)
    if hydra_config.mode != RunMode.MULTIRUN:
        run(cfg, given_keys)
        return
    # A sweep job trains in a process of its own, so that whatever ends it is reported at once,
    # naming the job and its run, while the other jobs go on (temporal_torchrl.runs.sweep_job).
    # A bad config is refused here first, before a process or a run directory is made for it.
    validate_recipe_config(cfg)
    cfg = sweep_job_config(cfg, hydra_config)
    if cfg is not None:
        job = f"#{hydra_config.job.num} ({' '.join(hydra_config.overrides.task)})"
        run_sweep_job(__file__, run.__name__, cfg, given_keys, job, run_directory(cfg))


if __name__ == "__main__":
    main()
