"""SAC with temporal VLM reward shaping on Metaworld (thesis chapter 5).

Each env step: act (uniform random during the warm-up), step the env (render -> embed -> history
-> reward, the reward only logged), then one reward-head update and one SAC update on batches from
the episode replay buffer, with SAC's rewards relabelled from the stored embeddings by the heads
as they are now. Each ended episode is labelled and inserted into the buffer (so SAC samples a
transition from the end of its episode on), then an episode row and a checkpoint are written.

    python recipes/sac_temporal.py                                # quick default (offline, CPU)
    python recipes/sac_temporal.py preset=best protocol=stage2 env.task=door-open env.seed=2
    python recipes/sac_temporal.py preset=best protocol=stage2 resume=true  # continue a killed run
    python recipes/sac_temporal.py output_dir=runs/x resume=true train.episodes=2000  # extend it

Outputs in ``output_dir`` (default: ``runs/<task>/<method>_<protocol>/seed<seed>``, see
``utils.default_run_dir``): ``episodes.csv`` (episode, env_steps, success, return = sum of sparse
task rewards, mean_vlm_reward, stage), ``summary.json`` (TTFS, TT50S, RAS, throughput, the
resolved config, the last training metrics), ``checkpoint.pt`` + ``replay/`` (resume), ``logs/``
(CSV logger: per-episode rows and, every ``logger.log_every`` updates, SAC's and the heads'
losses and the relabelled reward statistics) or ``wandb/``.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from collections.abc import Collection
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

import utils  # noqa: E402

from temporal_torchrl.data import embed_episode, goal_image_embedding, preload_experts  # noqa: E402,E501
from temporal_torchrl.envs import get_task  # noqa: E402
from temporal_torchrl.metrics import (  # noqa: E402
    DEFAULT_HORIZON,
    episode_success,
    ras,
    tt50s,
    ttfs,
)
from temporal_torchrl.objectives import finetuning_losses  # noqa: E402

# What an episode keeps from each step (pixels never reach the buffer).
STEP_KEYS = ("observation", "embedding", "action", "success", ("next", "observation"),
             ("next", "embedding"), ("next", "success"), ("next", "terminated"),
             ("next", "task_reward"), ("next", "vlm_reward"))


def train(cfg: DictConfig, given_keys: Collection[str] | None = None) -> dict | None:
    """Run (or resume) one training run; returns its summary, or None when stopped early.

    ``given_keys``: the keys set on the command line, which alone may change a resumed run's
    ``train.episodes`` and the other :data:`utils.RESUMABLE_KEYS` (None: all of ``cfg``'s do).
    """
    utils.validate_config(cfg)
    run_dir = utils.check_run_dir(cfg)
    if cfg.resume:
        cfg = utils.resumed_config(cfg, run_dir, given_keys)
        utils.validate_config(cfg)  # the saved config, continued, is the one that runs
    state = utils.load_checkpoint(run_dir) if cfg.resume else None
    if state is not None and state["episode"] >= cfg.train.episodes \
            and (run_dir / "summary.json").exists():
        print(f"{run_dir}: already complete ({state['episode']} episodes)")
        return json.loads((run_dir / "summary.json").read_text())
    torch.manual_seed(cfg.env.seed)

    # ---- encoder, reward, env
    vlm = utils.uses_vlm_reward(cfg)
    encoder = utils.make_encoder(cfg) if vlm else None
    reward = utils.make_temporal_reward(cfg, encoder) if vlm else None
    env = utils.make_environment(cfg, encoder, reward)
    print(f"run directory: {run_dir}")
    print(utils.describe_encoder(cfg, encoder))
    reward_transform = env.transform[-1] if vlm else None

    # ---- expert episodes: stage-2 positives and the goal image s_g
    finetune = vlm and (reward.positional_heads is not None
                        or reward.directional_heads is not None)
    needs_experts = cfg.train.preload_positives > 0 or finetune
    experts = (utils.collect_successful_experts(cfg, encoder, max(cfg.train.preload_positives, 1))
               if needs_experts and state is None else [])
    preloaded = [embed_episode(episode, encoder) if encoder is not None else episode
                 for episode in experts[:cfg.train.preload_positives]]
    losses, head_optimizers = [], []
    if finetune:
        goal_image = (state["goal_image"] if state is not None else
                      goal_image_embedding((preloaded or experts)[0], encoder))
        # Each part's registered objective: ranking (FuRL), directional (thesis 4.3.3) or
        # certainty (d_certainty).
        losses = finetuning_losses(reward, goal_image, delta=cfg.reward.delta,
                                   l2_margin=cfg.reward.l2_margin,
                                   same_position=cfg.reward.same_position)
        head_optimizers = [utils.make_adam(loss.parameters(), cfg.reward.lr) for loss in losses]

    # ---- SAC
    actor, qvalue = utils.make_sac_agent(cfg, env)
    sac_loss, target_updater, sac_optimizer = utils.make_sac_loss(
        cfg, actor, qvalue, env.action_spec.shape[-1])
    expert_rows = (sum(len(episode) + 1 for episode in preloaded) if state is None
                   else state["expert_rows"])
    capacity = utils.replay_capacity(cfg, expert_rows,
                                     saved=state["buffer_capacity"] if state else None)
    buffer = utils.make_replay_buffer(cfg, capacity,
                                      reward.window_length if reward is not None else None)

    # ---- fresh start or resume
    episode, env_steps, inserted, updates, successes = 0, 0, 0, 0, []
    last_metrics: dict[str, float] = {}
    if state is not None:
        sac_loss.load_state_dict(state["sac_loss"])
        sac_optimizer.load_state_dict(state["sac_optimizer"])
        if reward is not None:
            reward.load_state_dict(state["reward"])
        for optimizer, saved in zip(head_optimizers, state["head_optimizers"], strict=True):
            optimizer.load_state_dict(saved)
        episode, env_steps, inserted = state["episode"], state["env_steps"], state["inserted"]
        updates, last_metrics = state["updates"], state["last_metrics"]
        successes = list(state["successes"])
        utils.load_replay_episodes(run_dir, buffer, inserted, permanent=state["preloaded"])
        utils.truncate_episode_rows(run_dir, episode)
        utils.set_rng_state(state["rng"])
    else:
        utils.create_run_dir(run_dir)
        for rows in preload_experts(buffer, preloaded):
            utils.save_replay_episode(run_dir, inserted, rows)
            inserted += 1
        utils.write_json(run_dir / "config.json", OmegaConf.to_container(cfg, resolve=True))
    logger = utils.make_logger(cfg, run_dir)

    metrics = utils.MetricWindow()

    def update_reward_heads() -> None:
        batch = buffer.sample_finetuning(cfg.reward.batch_size, gap=cfg.reward.gap)
        for loss, optimizer in zip(losses, head_optimizers, strict=True):
            loss_td = loss(batch)
            value = loss_td[loss.loss_key]
            if value.requires_grad:
                optimizer.zero_grad(set_to_none=True)
                value.backward()
                optimizer.step()
            metrics.add("reward", loss_td.exclude("stage"))

    def update_sac() -> None:
        batch = buffer.sample(cfg.sac.batch_size)
        if reward_transform is not None:
            reward_transform(batch)  # relabel ("next", "reward") with the current heads
        loss_td = sac_loss(batch)
        total = loss_td["loss_actor"] + loss_td["loss_qvalue"] + loss_td["loss_alpha"]
        sac_optimizer.zero_grad(set_to_none=True)
        total.backward()
        sac_optimizer.step()
        target_updater.step()
        metrics.add("sac", loss_td.select("loss_actor", "loss_qvalue", "loss_alpha", "alpha",
                                          "entropy"))
        metrics.add("relabelled", utils.reward_statistics(batch["next"]))

    # ---- training loop
    start_time, start_steps = time.perf_counter(), env_steps
    bar = tqdm(total=cfg.train.episodes, initial=episode, disable=not cfg.train.progress,
               desc="episodes")
    while episode < cfg.train.episodes:
        stage = 2 if buffer.has_positives else 1
        tensordict, steps = env.reset(), []
        for _ in range(cfg.env.max_episode_steps):
            if env_steps < cfg.train.random_steps:
                tensordict["action"] = env.action_spec.rand()
            else:
                with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
                    actor(tensordict)
            tensordict = env.step(tensordict)
            steps.append(tensordict.select(*STEP_KEYS, strict=False))
            env_steps += 1
            if env_steps > cfg.train.random_steps and buffer.num_transitions > 0:
                for _ in range(cfg.train.reward_updates_per_step if losses else 0):
                    update_reward_heads()
                for _ in range(cfg.train.updates_per_step):
                    update_sac()
                    updates += 1
                    if updates % cfg.logger.log_every == 0:
                        last_metrics = metrics.flush()
                        last_metrics.update({"train/stage": 2.0 if buffer.has_positives else 1.0,
                                             "train/positive_states": buffer.num_positive_states})
                        utils.log_metrics(logger, last_metrics, env_steps)
            if tensordict["next", "done"].item():
                break
            tensordict = step_mdp(tensordict)

        # ---- episode end: label + insert, log, checkpoint
        trajectory = torch.stack(steps)
        rows = buffer.extend(trajectory)
        utils.save_replay_episode(run_dir, inserted, rows)
        inserted += 1
        episode += 1
        success = episode_success(trajectory["next", "success"])
        successes.append(success)
        task_rewards = trajectory.get(("next", "task_reward"),
                                      trajectory["next", "success"].float() - 1.0)
        vlm_rewards = trajectory.get(("next", "vlm_reward"), torch.zeros_like(task_rewards))
        row = {"episode": episode, "env_steps": env_steps, "success": int(success),
               "return": float(task_rewards.sum()), "mean_vlm_reward": float(vlm_rewards.mean()),
               "stage": stage}
        utils.append_episode_row(run_dir, row)
        if logger is not None:
            for key in ("success", "return", "mean_vlm_reward", "stage"):
                logger.log_scalar(f"train/{key}", float(row[key]), step=env_steps)
        elapsed = time.perf_counter() - start_time
        bar.update(1)
        bar.set_postfix(success_rate=f"{sum(successes) / len(successes):.2f}",
                        steps_per_s=f"{(env_steps - start_steps) / max(elapsed, 1e-9):.0f}")
        if episode % cfg.train.checkpoint_every == 0 or episode == cfg.train.episodes:
            utils.save_checkpoint(run_dir, {
                "sac_loss": sac_loss.state_dict(), "sac_optimizer": sac_optimizer.state_dict(),
                "reward": reward.state_dict() if reward is not None else {},
                "head_optimizers": [optimizer.state_dict() for optimizer in head_optimizers],
                "episode": episode, "env_steps": env_steps, "inserted": inserted,
                "updates": updates, "last_metrics": last_metrics,
                "successes": successes, "rng": utils.rng_state(),
                "goal_image": goal_image if finetune else None,
                "buffer_capacity": buffer.capacity,
                "preloaded": buffer.num_permanent_episodes, "expert_rows": expert_rows})
        if cfg.train.stop_after_episodes is not None and episode >= cfg.train.stop_after_episodes:
            bar.close()
            env.close()
            return None
    bar.close()
    env.close()

    # ---- summary
    elapsed = time.perf_counter() - start_time
    budget = get_task(cfg.env.task).ras_budget
    window = min(150, budget) if budget else 150
    summary = {
        "ttfs": ttfs(successes), "tt50s": tt50s(successes), "horizon": DEFAULT_HORIZON,
        "ras": {"value": ras(successes, budget, window) if budget else None,
                "budget": budget, "window": window},
        "episodes": episode, "env_steps": env_steps,
        "successes": int(sum(successes)),
        "steps_per_second": (env_steps - start_steps) / max(elapsed, 1e-9),
        "encoder": cfg.encoder.name if vlm else None,
        "updates": updates, "last_metrics": last_metrics,
        "config": OmegaConf.to_container(cfg, resolve=True),
    }
    utils.write_json(run_dir / "summary.json", summary)
    if logger is not None:
        for key in ("ttfs", "tt50s"):
            logger.log_scalar(f"summary/{key}", float(summary[key]), step=env_steps)
    return summary


@hydra.main(version_base=None, config_path=".", config_name="config")
def main(cfg: DictConfig) -> None:
    # Libraries log their progress at INFO (open_clip's model creation, TorchRL's storage); the
    # recipe prints its own lines and a progress bar, which those would interleave with.
    for name in ("", "torchrl"):
        logging.getLogger(name).setLevel(logging.WARNING)
    hydra_config = HydraConfig.get()
    if hydra_config.mode == RunMode.MULTIRUN:
        cfg = utils.sweep_job_config(cfg, hydra_config)
    if cfg.train.threads is not None:
        torch.set_num_threads(cfg.train.threads)
    summary = train(cfg, given_keys=utils.override_keys(hydra_config.overrides.task))
    if summary is not None:
        print({key: summary[key] for key in ("ttfs", "tt50s", "ras", "episodes", "env_steps",
                                              "steps_per_second")})


if __name__ == "__main__":
    main()
