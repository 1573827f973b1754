"""Compose the temporal env: the canonical factory, then the same transforms by hand.

    python examples/compose_env.py                   # the shipped encoder, frames at 64x64
    python examples/compose_env.py --encoder state   # no rendering (not a VLM): a fast check

Both envs give r = r_task + rho (r_P + lambda r_D) at every step; the script checks it.
"""

from __future__ import annotations

import argparse

from torchrl.envs import Compose

from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.envs import make_env, make_temporal_env, make_temporal_reward
from temporal_torchrl.params import EnvParams
from temporal_torchrl.transforms import (
    EmbeddingHistoryTransform,
    EmbeddingTransform,
    TemporalRewardTransform,
)


def combined(rollout, rho: float, lambda_: float):
    """r_task + rho (r_P + lambda r_D), from the reward parts the rollout logged."""
    return rollout["next", "task_reward"] + rho * (
        rollout["next", "positional_reward"] + lambda_ * rollout["next", "directional_reward"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="door-open")
    parser.add_argument("--encoder", default="metaworld_small", help="metaworld_small | state")
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args(argv)

    # [canonical]
    encoder = load_encoder(args.encoder)  # or load_encoder("liv", checkpoint="model.pt")
    reward = make_temporal_reward(args.task, encoder, positional="furl", directional="d3",
                                  baseline="generic", rho=1.0, lambda_=4.0, k=5)
    layout = EnvParams(args.task, seed=0)  # the task's env: layout, 500 steps, 64 px frames
    env = make_temporal_env(layout, encoder=encoder, reward=reward)
    rollout = env.rollout(args.steps)  # "embedding", "initial_embedding", "previous_embedding"
    # [/canonical]

    # [by-hand]
    renders = encoder.input_key == "pixels"  # the state encoder reads observations
    by_hand = make_env(layout, render=renders).append_transform(Compose(
        EmbeddingTransform(encoder),            # "pixels" -> "embedding" (pixels dropped)
        EmbeddingHistoryTransform(k=reward.k),  # -> "initial_embedding", "previous_embedding"
        TemporalRewardTransform(reward),        # -> r_P, r_D, "vlm_reward", total "reward"
    ))
    by_hand_rollout = by_hand.rollout(args.steps)
    # [/by-hand]

    for name, steps in (("make_temporal_env", rollout), ("by hand", by_hand_rollout)):
        error = (steps["next", "reward"] - combined(steps, reward.rho, reward.lambda_)).abs().max()
        assert error < 1e-5, f"{name}: the reward is not r_task + rho (r_P + lambda r_D)"
        assert "pixels" not in steps.keys(), f"{name}: pixels reached the rollout"
        print(f"{name}: {steps.shape[0]} steps, embedding {tuple(steps['embedding'].shape)}, "
              f"reward {steps['next', 'reward'].mean():+.3f} on average")
    assert set(rollout.keys(True)) == set(by_hand_rollout.keys(True))


if __name__ == "__main__":
    main()
