"""SAC with temporal VLM reward shaping on Metaworld (thesis chapter 5).

Each env step (a TorchRL collector: uniform random actions during the warm-up, then the actor's
samples; render -> embed -> history -> reward, the reward only logged) is followed by one
reward-head update and one SAC update on batches from the episode replay buffer, whose transform
relabels SAC's rewards from the stored embeddings with the heads as they are now. Each ended
episode is labelled and inserted into the buffer, then an episode row and a checkpoint are
written.

    python recipes/sac_temporal.py                                # quick default (offline, CPU)
    python recipes/sac_temporal.py preset=best protocol=stage2 env.task=door-open env.seed=2
    python recipes/sac_temporal.py preset=best protocol=stage2 resume=true  # continue a killed run
    python recipes/sac_temporal.py output_dir=runs/x resume=true train.episodes=2000  # extend it

Outputs in ``output_dir`` (default: ``runs/<task>/<method>_<protocol>/seed<seed>``, see
:func:`temporal_torchrl.runs.default_run_dir`; layout in
:mod:`temporal_torchrl.runs.directory`): ``episodes.csv`` (episode, env_steps, success, return =
sum of sparse task rewards, mean_vlm_reward, stage), ``summary.json`` (TTFS, TT50S, RAS,
throughput, the resolved config, the last training metrics), ``checkpoint.pt`` + ``replay/``
(resume), ``metrics.jsonl`` (whatever ``logger.backend``: per-episode rows and, every
``logger.log_every`` updates, SAC's and the heads' losses and the relabelled reward statistics;
what reports read) and the same in ``logs/`` (CSV logger) or ``wandb/``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Collection

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from temporal_torchrl.configs.rules import validate_recipe_config
from temporal_torchrl.data import episode_rows
from temporal_torchrl.envs import get_task
from temporal_torchrl.protocol_metrics import DEFAULT_HORIZON, episode_success, ras, tt50s, ttfs
from temporal_torchrl.runs import (
    RunDirectory,
    RunLockedError,
    override_keys,
    resumed_config,
    run_directory,
    sweep_job_config,
    uses_vlm_reward,
)
from temporal_torchrl.training import (
    MetricWindow,
    factories,
    log_metrics,
    reward_statistics,
    rng_state,
    set_rng_state,
)
from temporal_torchrl.training.relay import RelayExploration

# What an episode keeps from each step (pixels never reach the buffer).
STEP_KEYS = ("observation", "embedding", "action", "success", ("next", "observation"),
             ("next", "embedding"), ("next", "success"), ("next", "terminated"),
             ("next", "task_reward"), ("next", "vlm_reward"))


def train(cfg: DictConfig, given_keys: Collection[str] | None = None) -> dict | None:
    """Run (or resume) one training run; returns its summary, or None when stopped early.

    ``given_keys``: the keys set on the command line, which alone may change a resumed run's
    ``train.episodes`` and ``train.checkpoint_every`` (None: all of ``cfg``'s do). The run
    directory's lock is held throughout: ``RunLockedError`` at once when a live process holds it.
    """
    cfg = validate_recipe_config(cfg)
    run = RunDirectory(run_directory(cfg))
    with run.lock():  # one writer per run directory, for the whole run
        return _train(cfg, run, given_keys)


def _train(cfg: DictConfig, run: RunDirectory, given_keys: Collection[str] | None) -> dict | None:
    """:func:`train`, once the run's lock is held."""
    run.check(resume=cfg.resume, overwrite=cfg.overwrite)
    if cfg.resume:
        # The saved config, continued, is the one that runs: validated again.
        cfg = validate_recipe_config(resumed_config(cfg, run.path, given_keys))
    state = run.resume_state() if cfg.resume else None
    if state is not None and state["episode"] >= cfg.train.episodes and run.summary():
        print(f"{run.path}: already complete ({state['episode']} episodes)")
        return run.summary()
    torch.manual_seed(cfg.env.seed)

    # ---- encoder, reward, env
    encoder = factories.make_encoder(cfg) if uses_vlm_reward(cfg) else None
    reward = factories.make_reward(cfg, encoder) if encoder is not None else None
    env = factories.make_environment(cfg, encoder, reward)
    print(f"run directory: {run.path}")
    print(factories.describe_encoder(cfg, encoder))

    # ---- stage 2's preloaded positives and the goal image s_g
    finetune = reward is not None and (reward.positional_heads is not None
                                       or reward.directional_heads is not None)
    preloaded, goal_image = (factories.make_preloaded_positives(cfg, encoder, finetune)
                             if state is None else ([], state["goal_image"]))

    # ---- SAC, replay buffer, reward-head trainer
    actor, qvalue = factories.make_sac_agent(cfg, env)
    sac_loss, target_updater, sac_optimizer = factories.make_sac_loss(
        cfg, actor, qvalue, env.action_spec.shape[-1])
    update_sac = factories.make_sac_update(cfg, sac_loss, target_updater, sac_optimizer)
    expert_rows = (state["expert_rows"] if state is not None
                   else sum(len(rows) for rows in preloaded))
    saved_capacity = state["buffer_capacity"] if state is not None else None
    capacity = factories.replay_capacity(cfg, expert_rows, saved=saved_capacity)
    buffer = factories.make_replay_buffer(cfg, capacity, reward)
    embedding_dtype = getattr(torch, cfg.replay_buffer.embedding_dtype)
    trainer = None
    if finetune:
        trainer = factories.make_reward_trainer(cfg, reward, goal_image, buffer)

    # ---- fresh start or resume
    if state is None:
        run.create(config=OmegaConf.to_container(cfg, resolve=True))
        for index, rows in enumerate(preloaded):
            buffer.extend(rows)
            run.save_replay_episode(index, rows)
        episode, env_steps, inserted, updates = 0, 0, len(preloaded), 0
        successes, last_metrics, credits = [], {}, {"sac": 0.0, "reward": 0.0}
    else:
        sac_loss.load_state_dict(state["sac_loss"])
        sac_optimizer.load_state_dict(state["sac_optimizer"])
        if reward is not None:
            reward.load_state_dict(state["reward"])
        if trainer is not None:
            trainer.load_state_dict(state["trainer"])
        episode, env_steps, inserted = state["episode"], state["env_steps"], state["inserted"]
        updates, last_metrics = state["updates"], state["last_metrics"]
        successes = list(state["successes"])
        credits = dict(state.get("credits", {"sac": 0.0, "reward": 0.0}))
        for rows in run.replay_episodes(inserted):
            buffer.extend(rows)
    relay = (factories.make_relay(cfg, env, actor, buffer.num_positive_states)
             if cfg.train.relay and trainer is not None else None)
    if relay is not None and state is not None:
        relay.load_state_dict(state["relay"])
    print(f"relay exploration: {describe_relay(cfg, relay)}")
    collector = factories.make_collector(cfg, env, relay.policy if relay else actor,
                                         max(0, cfg.train.random_steps - env_steps))
    random_until = env_steps + collector.init_random_frames
    if state is not None:  # after every random draw the build makes
        set_rng_state(state["rng"])
    logger = factories.make_logger(cfg, run.path)
    metrics = MetricWindow()

    # ---- training loop: one vector step of env.num_envs envs, then its updates
    num_envs, start_time, start_steps = cfg.env.num_envs, time.perf_counter(), env_steps
    bar = tqdm(total=cfg.train.episodes, initial=episode, disable=not cfg.train.progress,
               desc="episodes")
    stages = [2 if buffer.has_positives else 1] * num_envs  # each env's episode's stage
    steps = [[] for _ in range(num_envs)]
    for data in collector:
        data = data.reshape(num_envs)
        for index in range(num_envs):
            steps[index].append(data[index].select(*STEP_KEYS, strict=False))
        env_steps += num_envs
        if env_steps > cfg.train.random_steps and buffer.num_transitions > 0:
            # The update-to-data ratio holds at any num_envs; fractions carry over.
            credits["reward"] += num_envs * cfg.train.reward_updates_per_step * (
                trainer is not None)
            credits["sac"] += num_envs * cfg.train.utd_ratio
            while credits["reward"] >= 1:
                metrics.add("reward", trainer.update())
                credits["reward"] -= 1
            while credits["sac"] >= 1:
                batch = buffer.sample()  # rewards relabelled with the current heads
                relay_batch = (relay.task_reward_batch(batch)
                               if relay is not None and relay.schedule.active else None)
                metrics.add("sac", update_sac(batch))
                if relay_batch is not None:  # the relay agent learns from the same batches
                    metrics.add("relay", relay.update(relay_batch))
                metrics.add("relabelled", reward_statistics(batch["next"]))
                credits["sac"] -= 1
                updates += 1
                if updates % cfg.logger.log_every == 0:
                    last_metrics = metrics.flush()
                    last_metrics.update({"train/stage": 2.0 if buffer.has_positives else 1.0,
                                         "train/positive_states": buffer.num_positive_states})
                    log_metrics(logger, last_metrics, env_steps)
        ended = data["next", "done"].reshape(num_envs).nonzero().reshape(-1).tolist()
        if relay is not None:
            relay.schedule.advance(ended, acted=env_steps > random_until)
        if not ended:
            continue

        # ---- episode ends (in env order): label + insert, log, checkpoint
        checkpointed_before = episode // cfg.train.checkpoint_every
        for index in ended[:cfg.train.episodes - episode]:
            trajectory, steps[index] = torch.stack(steps[index]), []
            rows = episode_rows(trajectory, embedding_dtype=embedding_dtype)
            buffer.extend(rows)
            run.save_replay_episode(inserted, rows)
            inserted += 1
            episode += 1
            success = episode_success(trajectory["next", "success"])
            successes.append(success)
            if success and cfg.train.save_positives:
                run.save_positive_episode(episode, rows)
            task_rewards = trajectory.get(("next", "task_reward"),
                                          trajectory["next", "success"].float() - 1.0)
            vlm_rewards = trajectory.get(("next", "vlm_reward"), torch.zeros_like(task_rewards))
            row = {"episode": episode, "env_steps": env_steps, "success": int(success),
                   "return": float(task_rewards.sum()),
                   "mean_vlm_reward": float(vlm_rewards.mean()), "stage": stages[index]}
            run.append_episode(row)
            episode_metrics = {f"train/{key}": float(row[key]) for key in
                               ("success", "return", "mean_vlm_reward", "stage")}
            if relay is not None:
                episode_metrics["train/relay_fraction"] = (
                    relay.schedule.episode_relay_steps(index) / len(trajectory))
            log_metrics(logger, episode_metrics, env_steps)
            stages[index] = 2 if buffer.has_positives else 1
            bar.update(1)
        if relay is not None:
            relay.schedule.end_if_enough(buffer.num_positive_states)
        elapsed = time.perf_counter() - start_time
        bar.set_postfix(success_rate=f"{sum(successes) / len(successes):.2f}",
                        steps_per_s=f"{(env_steps - start_steps) / max(elapsed, 1e-9):.0f}")
        if (episode // cfg.train.checkpoint_every > checkpointed_before
                or episode >= cfg.train.episodes):
            run.save_checkpoint({
                "sac_loss": sac_loss.state_dict(), "sac_optimizer": sac_optimizer.state_dict(),
                "reward": reward.state_dict() if reward is not None else {},
                "trainer": trainer.state_dict() if trainer is not None else {},
                "goal_image": goal_image if trainer is not None else None,
                "episode": episode, "env_steps": env_steps, "inserted": inserted,
                "updates": updates, "credits": credits, "last_metrics": last_metrics,
                "successes": successes, "rng": rng_state(), "buffer_capacity": buffer.capacity,
                "preloaded": buffer.num_permanent_episodes, "expert_rows": expert_rows,
                "relay": relay.state_dict() if relay is not None else {}})
        stopped = (cfg.train.stop_after_episodes is not None
                   and episode >= cfg.train.stop_after_episodes)
        if episode >= cfg.train.episodes or stopped:
            break
    bar.close()
    collector.shutdown()
    if episode < cfg.train.episodes:
        return None  # stopped early, as if killed (train.stop_after_episodes)
    if metrics.pending:  # the last window, shorter than logger.log_every updates
        last_metrics = metrics.flush()
        last_metrics.update({"train/stage": 2.0 if buffer.has_positives else 1.0,
                             "train/positive_states": buffer.num_positive_states})
        log_metrics(logger, last_metrics, env_steps)

    # ---- summary
    elapsed = time.perf_counter() - start_time
    budget = get_task(cfg.env.task).ras_budget
    window = min(150, budget) if budget else 150
    summary = {
        "ttfs": ttfs(successes), "tt50s": tt50s(successes), "horizon": DEFAULT_HORIZON,
        "ras": {"value": ras(successes, budget, window) if budget else None,
                "budget": budget, "window": window},
        "episodes": episode, "env_steps": env_steps, "successes": int(sum(successes)),
        "steps_per_second": (env_steps - start_steps) / max(elapsed, 1e-9),
        "encoder": cfg.encoder.name if encoder is not None else None,
        "updates": updates, "last_metrics": last_metrics,
        "relay_steps": relay.schedule.total_relay_steps if relay is not None else 0,
        "config": OmegaConf.to_container(cfg, resolve=True),
    }
    run.write_summary(summary)
    log_metrics(logger, {f"summary/{key}": float(summary[key]) for key in ("ttfs", "tt50s")},
                env_steps)
    return summary


def describe_relay(cfg: DictConfig, relay: RelayExploration | None) -> str:
    if relay is None:
        return ("off (train.relay=false)" if not cfg.train.relay
                else "off (no finetuned reward heads to relay for)")
    if not relay.schedule.active:
        return f"off (the positives already reach train.relay_threshold={relay.schedule.threshold})"
    return (f"on until {relay.schedule.threshold:,} positive states (periods "
            f"{list(cfg.train.relay_periods)}, noise {cfg.train.relay_noise})")


@hydra.main(version_base=None, config_path=".", config_name="config")
def main(cfg: DictConfig) -> None:
    # Libraries log their progress at INFO (open_clip's model creation, TorchRL's storage); the
    # recipe prints its own lines and a progress bar, which those would interleave with.
    for name in ("", "torchrl"):
        logging.getLogger(name).setLevel(logging.WARNING)
    hydra_config = HydraConfig.get()
    if hydra_config.mode == RunMode.MULTIRUN:
        cfg = sweep_job_config(cfg, hydra_config)
    if cfg.train.threads is not None:
        torch.set_num_threads(cfg.train.threads)
    try:
        summary = train(cfg, given_keys=override_keys(hydra_config.overrides.task))
    except RunLockedError as error:
        if hydra_config.mode != RunMode.MULTIRUN:
            raise
        print(error.skip_line())  # the other jobs of the sweep go on
        return
    if summary is not None:
        print({key: summary[key] for key in ("ttfs", "tt50s", "ras", "episodes", "env_steps",
                                              "steps_per_second")})


if __name__ == "__main__":
    main()
