"""Your own reward: a function of the heads and embeddings, registered under a name.

Registered, it is used like a built-in by TemporalReward, the finetuning losses, the recipe and
the offline benchmark:

    python recipes/sac_temporal.py reward.modules=[examples/my_rewards.py] reward.positional=p5
    python recipes/evaluate_rewards.py reward.modules=[examples/my_rewards.py] \\
        reward.positional=[furl,p5] reward.directional=none
    python examples/my_rewards.py --encoder state     # p5 in a composed env, a few steps
"""

from __future__ import annotations

import argparse

from temporal_torchrl.rewards import cosine_similarity, register_reward


# [reward]
def progress_since_start(heads, s, *, g, s0=None, **unused):
    """csim(f_I(s_t) - f_I(s_0), f_L(g)): P2 without the baseline."""
    return cosine_similarity(heads.image(s) - heads.image(s0), heads.text(g))


register_reward("p5", progress_since_start, kind="positional")
# [/reward]


def main(argv: list[str] | None = None) -> None:
    from temporal_torchrl.encoders import load_encoder
    from temporal_torchrl.envs import make_temporal_env, make_temporal_reward
    from temporal_torchrl.params import EnvParams

    parser = argparse.ArgumentParser(description="p5 in a composed env")
    parser.add_argument("--task", default="drawer-open")
    parser.add_argument("--encoder", default="metaworld_small", help="metaworld_small | state")
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args(argv)

    encoder = load_encoder(args.encoder)
    reward = make_temporal_reward(args.task, encoder, positional="p5", directional=None, rho=1.0)
    env = make_temporal_env(EnvParams(args.task, seed=0), encoder=encoder, reward=reward)
    rollout = env.rollout(args.steps)
    r_p = rollout["next", "positional_reward"].squeeze(-1)
    print("p5 along", args.steps, "random steps:", " ".join(f"{value:+.2f}" for value in r_p))


if __name__ == "__main__":
    main()
