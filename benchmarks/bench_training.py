"""Training throughput and replay-buffer costs, each next to a raw TorchRL reference.

Rows:
1. whole loop, state encoder (D = 1024, FuRL + D3, one head update and one SAC update per step,
   batch 256) vs a plain TorchRL SAC loop on the same env (TensorDictReplayBuffer, same networks
   and update schedule), env steps/s; and the recipe without a VLM reward against the same
   reference (the recipe's own overhead: episode buffer, logging, checkpoints);
2. whole loop with rendering + a random-weight LIV encoder (256x256 frames) vs the same env
   pipeline stepping without any training, env steps/s;
3. sampling 256 sub-trajectories at 500,000 transitions (D = 1024): EpisodeReplayBuffer.sample
   (a TorchRL ReplayBuffer: s_{t+1}, s_0, s_{t+1-k} by index, laid out for SAC by its
   transform) vs TorchRL's SliceSampler(slice_len=2) on a LazyTensorStorage with the same
   float16 embeddings; and a finetuning batch (stage 2: 256 negatives, positives, pairs);
4. replay memory at 500,000 transitions vs storing s_t and s_{t+1} as float32 (the naive layout).

Runs on one torch thread (the machine may be shared). ``--quick`` shortens every timing.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import torch
from _common import parse_args, report, seconds_per_call
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, SliceSampler, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
sys.path.insert(0, str(RECIPES))

import sac_temporal  # noqa: E402
import utils  # noqa: E402

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows  # noqa: E402
from temporal_torchrl.envs import make_env  # noqa: E402


def recipe_config(output_dir: Path, *overrides: str):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("config", overrides=[
            f"output_dir={output_dir}", "logger.backend=none", "train.progress=false",
            "train.random_steps=0", "reward.directional=d3", "reward.lambda_=4.0",
            "reward.rho=1.0", *overrides])


def plain_sac_steps_per_second(cfg, episodes: int) -> float:
    """The reference: TorchRL env.step + per-step buffer extend + SACLoss update, no VLM."""
    env = make_env(cfg.env.task, cfg.env.seed, max_episode_steps=cfg.env.max_episode_steps)
    actor, qvalue = utils.make_sac_agent(cfg, env)
    loss, updater, optimizer = utils.make_sac_loss(cfg, actor, qvalue, 4)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(episodes * 1000),
                                    batch_size=cfg.sac.batch_size)
    steps = 0
    start = time.perf_counter()
    for _ in range(episodes):
        tensordict = env.reset()
        for _ in range(cfg.env.max_episode_steps):
            with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
                actor(tensordict)
            tensordict = env.step(tensordict)
            buffer.add(tensordict.select("observation", "action", "next").exclude(
                ("next", "pixels")))
            steps += 1
            if steps > cfg.env.max_episode_steps:  # the recipe updates from its 2nd episode on
                losses = loss(buffer.sample())
                optimizer.zero_grad()
                (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
                optimizer.step()
                updater.step()
            if tensordict["next", "done"].item():
                break
            tensordict = step_mdp(tensordict)
    return steps / (time.perf_counter() - start)


def pipeline_steps_per_second(cfg, steps: int) -> float:
    """Reference for the rendering row: the render -> embed -> reward env, no training."""
    encoder = utils.make_encoder(cfg)
    env = utils.make_environment(cfg, encoder, utils.make_reward(cfg, encoder))
    env.rollout(2, break_when_any_done=False)
    start = time.perf_counter()
    env.rollout(steps, break_when_any_done=False)
    return steps / (time.perf_counter() - start)


def filled_buffers(transitions: int, dim: int = 1024, episode_length: int = 500):
    """The project's buffer and a TorchRL SliceSampler buffer, both with ``transitions``."""
    episodes = transitions // episode_length
    ours = EpisodeReplayBuffer(capacity=episodes * (episode_length + 1), history=5,
                               permanent_episodes=1)
    reference = TensorDictReplayBuffer(
        storage=LazyTensorStorage(transitions),
        sampler=SliceSampler(slice_len=2, traj_key="episode", strict_length=True,
                             truncated_key=None), batch_size=512)
    done = torch.zeros(episode_length, 1, dtype=torch.bool)
    done[-1] = True
    for index in range(episodes):
        embedding = torch.randn(episode_length + 1, dim)
        observation = torch.randn(episode_length + 1, 39)
        success = torch.zeros(episode_length, 1, dtype=torch.bool)
        if index == 0:  # one successful episode: the finetuning batch has every group
            success[400:] = True
        episode = TensorDict({
            "observation": observation[:-1], "embedding": embedding[:-1],
            "action": torch.rand(episode_length, 4), "success": success,
            "next": {"observation": observation[1:], "embedding": embedding[1:],
                     "success": success, "terminated": torch.zeros_like(done), "done": done},
        }, [episode_length])
        ours.extend(episode_rows(episode))
        flat = TensorDict({
            "observation": observation[:-1], "action": episode["action"],
            "episode": torch.full((episode_length,), index),
            "next": {"observation": observation[1:], "embedding": embedding[1:].half(),
                     "done": done, "terminated": torch.zeros_like(done)}}, [episode_length])
        reference.extend(flat)
    return ours, reference


def main() -> None:
    args = parse_args(__doc__.splitlines()[0])
    torch.set_num_threads(1)
    quick = args.quick
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # 1. whole loop, state encoder
        episodes, length = (3, 100) if quick else (4, 250)
        cfg = recipe_config(tmp / "state", "encoder.name=state", f"train.episodes={episodes}",
                            f"env.max_episode_steps={length}")
        summary = sac_temporal.train(cfg)
        reference = plain_sac_steps_per_second(cfg, episodes)
        rows.append({"measure": "whole loop, state encoder, FuRL + D3, D=1024 (env steps/s)",
                     "project": summary["steps_per_second"],
                     "reference": reference, "reference is": "plain TorchRL SAC loop",
                     "ratio": summary["steps_per_second"] / reference})

        # 1b. the same loop without the VLM reward: the recipe's own overhead
        cfg = recipe_config(tmp / "sac", f"train.episodes={episodes}",
                            f"env.max_episode_steps={length}", "reward.positional=none",
                            "reward.directional=none")
        summary = sac_temporal.train(cfg)
        rows.append({"measure": "whole loop, no VLM reward (env steps/s)",
                     "project": summary["steps_per_second"],
                     "reference": reference, "reference is": "plain TorchRL SAC loop",
                     "ratio": summary["steps_per_second"] / reference})

        # 2. whole loop, rendering + LIV-format encoder (random weights)
        from temporal_torchrl.encoders import save_random_liv_checkpoint

        checkpoint = tmp / "liv.pt"
        save_random_liv_checkpoint(checkpoint)
        length = 10 if quick else 30
        cfg = recipe_config(tmp / "liv", "encoder.name=liv", f"encoder.checkpoint={checkpoint}",
                            "env.image_size=256", "train.episodes=2",
                            f"env.max_episode_steps={length}")
        summary = sac_temporal.train(cfg)
        reference = pipeline_steps_per_second(cfg, length)
        rows.append({"measure": "whole loop, render 256px + LIV RN50 (env steps/s)",
                     "project": summary["steps_per_second"], "reference": reference,
                     "reference is": "same env pipeline, no training",
                     "ratio": summary["steps_per_second"] / reference})

    # 3. and 4. the replay buffer at 500,000 transitions
    transitions = 500_000
    ours, reference = filled_buffers(transitions)
    minimum = 0.5 if quick else 2.0
    ours_seconds = seconds_per_call(lambda: ours.sample(256), min_seconds=minimum)
    reference_seconds = seconds_per_call(lambda: reference.sample(), min_seconds=minimum)
    rows.append({"measure": "sample 256 sub-trajectories at 500k (ms)",
                 "project": 1000 * ours_seconds, "reference": 1000 * reference_seconds,
                 "reference is": "SliceSampler(slice_len=2), float16 embeddings",
                 "ratio": ours_seconds / reference_seconds})
    finetuning_seconds = seconds_per_call(lambda: ours.finetuning.sample(256),
                                          min_seconds=minimum)
    rows.append({"measure": "finetuning batch (256 negatives, positives, pairs) at 500k (ms)",
                 "project": 1000 * finetuning_seconds, "reference": 1000 * reference_seconds,
                 "reference is": "SliceSampler(slice_len=2), float16 embeddings",
                 "ratio": finetuning_seconds / reference_seconds})
    naive = transitions * (2 * 1024 * 4 + 2 * 39 * 4 + 4 * 4 + 4)
    rows.append({"measure": "replay memory at 500k transitions, D=1024 (GB)",
                 "project": ours.memory_bytes() / 1e9, "reference": naive / 1e9,
                 "reference is": "s_t and s_t+1 as float32 (computed)",
                 "ratio": ours.memory_bytes() / naive})
    report("Training loop and replay buffer", rows, args.json)


if __name__ == "__main__":
    main()
