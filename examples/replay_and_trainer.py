"""A replay buffer and the reward-head trainer by hand, as the recipe runs them.

    python examples/replay_and_trainer.py                  # the shipped encoder, frames at 64x64
    python examples/replay_and_trainer.py --encoder state  # no rendering: seconds

One scripted-expert episode (positive; its first success state is the goal image s_g) and a few
random-action episodes (negative) go into an EpisodeReplayBuffer; SAC's batches come out with
rewards relabelled by the heads as they are now, and RewardHeadTrainer finetunes the heads on
the same storage.
"""

from __future__ import annotations

import argparse

from temporal_torchrl.data import (
    EpisodeReplayBuffer,
    embed_episode,
    episode_rows,
    goal_image_embedding,
)
from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.envs import (
    collect_successful_experts,
    make_temporal_env,
    make_temporal_reward,
)
from temporal_torchrl.params import EnvParams
from temporal_torchrl.training import RewardHeadTrainer


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="drawer-open")
    parser.add_argument("--encoder", default="metaworld_small", help="metaworld_small | state")
    parser.add_argument("--episodes", type=int, default=3, help="random-action episodes")
    parser.add_argument("--steps", type=int, default=50, help="steps per random episode")
    parser.add_argument("--updates", type=int, default=20, help="reward-head updates")
    args = parser.parse_args(argv)

    encoder = load_encoder(args.encoder)
    reward = make_temporal_reward(args.task, encoder, positional="furl", directional="d3",
                                  rho=1.0, lambda_=4.0, k=5)
    renders = encoder.input_key == "pixels"
    layout = EnvParams(args.task, seed=0)      # 64x64 frames of the seed's layout
    env = make_temporal_env(layout.replace(max_episode_steps=args.steps), encoder=encoder,
                            reward=reward)

    # [buffer]
    buffer = EpisodeReplayBuffer(100_000, reward=reward, batch_size=256)
    expert = collect_successful_experts(layout, count=1, render=renders)[0]
    expert = embed_episode(expert, encoder)     # the env's embeddings, for the expert's states
    buffer.extend(episode_rows(expert))         # one ended episode: T + 1 rows, labelled
    for _ in range(args.episodes):
        buffer.extend(episode_rows(env.rollout(args.steps)))  # random actions: negatives
    batch = buffer.sample()                     # SAC transitions, ("next", "reward") relabelled
    # [/buffer]
    print(f"buffer: {len(buffer)} transitions; a SAC batch of {batch.shape[0]}, "
          f"reward {batch['next', 'reward'].mean():+.3f} on average")

    # [trainer]
    goal_image = goal_image_embedding(expert)   # s_g: the expert's first success state
    trainer = RewardHeadTrainer(reward, goal_image, buffer.finetuning, batch_size=64)
    for _ in range(args.updates):
        metrics = trainer.update()              # one step per loss; a TensorDict of loss terms
    # [/trainer]
    print("after", args.updates, "updates:",
          ", ".join(f"{key} {float(value):.3f}" for key, value in sorted(metrics.items())))
    relabelled = buffer.sample()["next", "reward"]
    print(f"the same buffer, relabelled by the updated heads: {relabelled.mean():+.3f}")


if __name__ == "__main__":
    main()
