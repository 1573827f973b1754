"""Reward relabelling and the per-step cost of the history and reward transforms.

Rows:
1. Relabelling a sampled batch of 256 transitions with FuRL + D3 at D = 1024 (CPU target
   <= 1 ms) through ``TemporalRewardTransform`` on a TensorDict, against the same math written
   inline as plain torch ops on the same tensors and weights.
2. An env rollout (Metaworld drawer-open, the render-free ``state`` encoder) with and without the
   history and reward transforms: the difference per step is their cost.

Run: ``python benchmarks/bench_rewards.py [--quick | --smoke] [--json out.json]``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from _common import parse_args, report, seconds_per_call
from tensordict import TensorDict

from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.transforms import EmbeddingHistoryTransform, TemporalRewardTransform

BATCH, DIM = 256, 1024
ROUNDS = 5


def _paired_seconds(project: Callable[[], object], reference: Callable[[], object],
                    min_seconds: float, warmup_calls: int = 2) -> tuple[float, float]:
    """Best-of-rounds seconds per call of both, alternating rounds: on a shared machine a
    single long measurement of each would compare different loads."""
    project_times, reference_times = [], []
    for _ in range(ROUNDS):
        project_times.append(seconds_per_call(project, min_seconds / ROUNDS, warmup_calls))
        reference_times.append(seconds_per_call(reference, min_seconds / ROUNDS, warmup_calls))
    return min(project_times), min(reference_times)


def _raw_relabel(reward: TemporalReward, s, s0, s_prev, success):
    """FuRL + D3 inline: r = success - 1 + rho (csim(f_I(s), f_L(g)) + lambda csim(...))."""
    def mlp(head, x):
        return F.linear(F.relu(F.linear(x, head[0].weight, head[0].bias)), head[2].weight,
                        head[2].bias)

    g, b = reward.goal_embedding, reward.baseline_embedding
    ph, dh = reward.positional_heads, reward.directional_heads
    r_p = F.cosine_similarity(mlp(ph.image, s), mlp(ph.text, g).unsqueeze(0), dim=-1)
    direction = s - s_prev
    image_input = torch.cat((F.normalize(s, dim=-1), F.normalize(direction, dim=-1)), dim=-1)
    r_d = F.cosine_similarity(mlp(dh.image, image_input), mlp(dh.text, g - b).unsqueeze(0), dim=-1)
    return success.float() - 1 + reward.rho * (r_p + reward.lambda_ * r_d).unsqueeze(-1)


def bench_relabel(min_seconds: float) -> dict:
    reward = TemporalReward(DIM, torch.randn(DIM), torch.randn(DIM), positional="furl",
                            directional="d3", rho=1.0, lambda_=4.0)
    s, s0, s_prev = (torch.randn(BATCH, DIM) for _ in range(3))
    success = torch.rand(BATCH, 1) < 0.3
    batch = TensorDict({"next": {"embedding": s, "initial_embedding": s0,
                                 "previous_embedding": s_prev, "success": success}}, [BATCH])
    transform = TemporalRewardTransform(reward)
    relabelled = transform(batch)["next", "reward"]
    with torch.no_grad():
        raw = _raw_relabel(reward, s, s0, s_prev, success)
    torch.testing.assert_close(relabelled, raw, rtol=1e-4, atol=1e-5)

    def raw_call():
        with torch.no_grad():
            _raw_relabel(reward, s, s0, s_prev, success)

    project, reference = _paired_seconds(lambda: transform(batch), raw_call, min_seconds)
    return {"case": f"relabel batch {BATCH}, FuRL + D3, D={DIM}", "project_ms": project * 1e3,
            "raw_ms": reference * 1e3, "ratio": project / reference}


def bench_rollout(steps: int, min_seconds: float) -> dict | None:
    try:
        from torchrl.envs import Compose, TransformedEnv

        from temporal_torchrl.encoders import load_encoder
        from temporal_torchrl.envs import make_env
        from temporal_torchrl.transforms import EmbeddingTransform
    except ImportError as error:
        print(f"rollout row skipped: {error}")
        return None
    encoder = load_encoder("state")
    reward = TemporalReward(encoder.dim, torch.randn(encoder.dim), torch.randn(encoder.dim),
                            positional="furl", directional="d3", rho=1.0, lambda_=4.0)
    base = TransformedEnv(make_env("drawer-open", max_episode_steps=steps),
                          EmbeddingTransform(encoder))
    full = TransformedEnv(make_env("drawer-open", max_episode_steps=steps),
                          Compose(EmbeddingTransform(encoder), EmbeddingHistoryTransform(reward.k),
                                  TemporalRewardTransform(reward)))
    with_transforms, without = _paired_seconds(
        lambda: full.rollout(steps, break_when_any_done=False),
        lambda: base.rollout(steps, break_when_any_done=False), min_seconds, warmup_calls=1)
    return {"case": f"env step + history + reward (drawer-open, state encoder D={encoder.dim})",
            "project_ms": with_transforms / steps * 1e3, "raw_ms": without / steps * 1e3,
            "ratio": with_transforms / without,
            "transforms_ms_per_step": (with_transforms - without) / steps * 1e3}


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    min_seconds, steps = (0.05, 10) if args.smoke else (0.5, 50) if args.quick else (2.0, 100)
    rows = [bench_relabel(min_seconds)]
    rollout = bench_rollout(steps, min_seconds)
    if rollout is not None:
        rows[0]["transforms_ms_per_step"] = float("nan")
        rows.append(rollout)
    report("Rewards: relabelling and transform cost", rows, args.json)


if __name__ == "__main__":
    main()
