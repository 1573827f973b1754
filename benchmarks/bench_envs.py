"""Throughput of the envs module against raw references measured in the same run.

Rows:
- render (fast / default): frames/s of ``RenderTransform`` (its env-step path, rotation
  included) vs a raw ``mujoco.Renderer`` with the same settings, both drawing the same state
  of ``push`` from ``corner2`` at 224x224 (targets on 2 CPU cores: fast >= 100 frames/s and
  within 10% of raw).
- env step: steps/s of ``make_env(...).rollout`` without rendering (random actions, auto-reset)
  vs the raw Metaworld/gymnasium env stepped in a Python loop with random actions (target:
  >= 0.8x raw).
- env step + fast render: the same with ``render=True`` vs raw step + raw render, timed with
  ``rollout`` (which stacks all frames at the end) and with a ``step_and_maybe_reset`` loop.

``--smoke``: 64x64 frames, a few steps, one round.
Run: ``python benchmarks/bench_envs.py [--quick | --smoke] [--json out.json]``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import mujoco
import numpy as np
from _common import parse_args, rate, report
from metaworld.env_dict import ALL_V3_ENVIRONMENTS_GOAL_HIDDEN

from temporal_torchrl.defaults import CAMERA
from temporal_torchrl.envs import make_env

TASK = "push"
SIZE = 224


def compare(project_fn, raw_fn, items_per_call: int, seconds: float, rounds: int = 3
            ) -> tuple[float, float]:
    """Best rate of each over ``rounds`` alternating timings (the machine is shared and noisy;
    alternating and keeping the best of each makes the ratio fair to both)."""
    project, raw = 0.0, 0.0
    for _ in range(rounds):
        project = max(project, rate(project_fn, items_per_call, seconds / rounds))
        raw = max(raw, rate(raw_fn, items_per_call, seconds / rounds))
    return project, raw


def raw_renderer(model: mujoco.MjModel, fast: bool, size: int = SIZE) -> mujoco.Renderer:
    """A plain ``mujoco.Renderer`` with the fast settings applied as the transform does."""
    if fast:
        model.vis.quality.shadowsize = 0
        model.vis.quality.offsamples = 0
    renderer = mujoco.Renderer(model, height=size, width=size)
    if fast:
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    return renderer


def bench_render(fast: bool, seconds: float, rounds: int = 3, size: int = SIZE) -> dict:
    env = make_env(TASK, render=True, image_size=size, camera=CAMERA, fast_render=fast)
    tensordict = env.reset()
    transform = env.transform
    raw_env = ALL_V3_ENVIRONMENTS_GOAL_HIDDEN[f"{TASK}-v3-goal-hidden"](seed=0)
    raw_env.reset()
    renderer = raw_renderer(raw_env.model, fast, size)

    def raw_frame() -> np.ndarray:
        renderer.update_scene(raw_env.data, CAMERA)
        return renderer.render()

    project, raw = compare(lambda: transform._call(tensordict), raw_frame, 1, seconds, rounds)
    renderer.close()
    env.close()
    mode = "fast" if fast else "default"
    return {"benchmark": f"render {mode} {size}x{size} (frames/s)", "project": project,
            "raw": raw, "ratio": project / raw}


def raw_stepper(render: bool, steps: int, size: int = SIZE) -> Callable[[], None]:
    env = ALL_V3_ENVIRONMENTS_GOAL_HIDDEN[f"{TASK}-v3-goal-hidden"](seed=0)
    env.reset()
    renderer = raw_renderer(env.model, fast=True, size=size) if render else None

    def run() -> None:
        for _ in range(steps):
            _, _, _, truncated, _ = env.step(env.action_space.sample())
            if renderer is not None:
                renderer.update_scene(env.data, CAMERA)
                renderer.render()
            if truncated:
                env.reset()

    return run


def bench_steps(render: bool, steps: int, seconds: float, stack: bool = True,
                rounds: int = 3, size: int = SIZE) -> dict:
    """``stack=False`` times ``step_and_maybe_reset`` in a loop (what a collector does per
    step) instead of ``rollout``, whose final ``torch.stack`` of all frames is TorchRL's cost,
    not the env's."""
    env = make_env(TASK, render=render, image_size=size, camera=CAMERA)

    def step_loop() -> None:
        tensordict = env.reset()
        for _ in range(steps):
            _, tensordict = env.step_and_maybe_reset(env.rand_action(tensordict))

    project_fn = (lambda: env.rollout(steps, break_when_any_done=False)) if stack else step_loop
    project, raw = compare(project_fn, raw_stepper(render, steps, size), steps, seconds, rounds)
    env.close()
    label = "env step + fast render" if render else "env step, no rendering"
    how = "rollout" if stack else "step loop"
    return {"benchmark": f"{label}, {how} (steps/s)", "project": project, "raw": raw,
            "ratio": project / raw}


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    seconds, steps, render_steps, rounds, size = ((0.01, 10, 3, 1, 64) if args.smoke
                                                  else (1.5, 500, 100, 3, SIZE) if args.quick
                                                  else (4.0, 500, 250, 3, SIZE))
    rows = [
        bench_render(fast=True, seconds=seconds, rounds=rounds, size=size),
        bench_render(fast=False, seconds=seconds, rounds=rounds, size=size),
        bench_steps(render=False, steps=steps, seconds=seconds, rounds=rounds, size=size),
        bench_steps(render=True, steps=render_steps, seconds=seconds, rounds=rounds, size=size),
        bench_steps(render=True, steps=render_steps, seconds=seconds, stack=False,
                    rounds=rounds, size=size),
    ]
    report(f"envs: {TASK}, camera {CAMERA}", rows, args.json)


if __name__ == "__main__":
    main()
