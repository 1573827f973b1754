"""Demo: build a fixed-goal Metaworld task, render a few frames and run one scripted-expert episode.

Run: ``python recipes/demo_envs.py [--task drawer-open] [--seed 0] [--output-dir outputs/demo]``.
Writes ``<output-dir>/<task>_frame.png`` (the first rendered frame) and
``<output-dir>/<task>_expert_goal.png`` (the expert's first success frame, a goal image s_g).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch
from PIL import Image

from temporal_torchrl import defaults
from temporal_torchrl.envs import (
    EVALUATION_TASKS,
    collect_expert_episodes,
    first_success_index,
    get_task,
    make_env,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="drawer-open",
                        help=f"short Metaworld task name (evaluation tasks: {EVALUATION_TASKS})")
    parser.add_argument("--seed", type=int, default=0, help="layout seed")
    parser.add_argument("--image-size", type=int, default=224)
    parser.add_argument("--camera", default=defaults.CAMERA)
    parser.add_argument("--frames", type=int, default=5, help="random-action frames to render")
    parser.add_argument("--output-dir", default="outputs/demo")
    args = parser.parse_args()

    task = get_task(args.task)
    output_dir = Path(args.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    print(f"task {task.name}: goal prompt {task.goal_prompt!r}, baseline {task.baseline!r}")

    env = make_env(task.name, seed=args.seed, render=True, image_size=args.image_size,
                   camera=args.camera)
    start = time.perf_counter()
    rollout = env.rollout(args.frames)
    elapsed = time.perf_counter() - start
    frames = torch.cat([rollout["pixels"][:1], rollout["next", "pixels"]])
    frame_path = output_dir / f"{task.name}_frame.png"
    Image.fromarray(frames[0].numpy()).save(frame_path)
    print(f"rendered {len(frames)} frames of shape {tuple(frames.shape[1:])} "
          f"({args.frames / elapsed:.1f} steps/s with rendering); saved {frame_path}")
    env.close()

    episode, = collect_expert_episodes(task.name, seed=args.seed, noise=0.1, render=True,
                                       image_size=args.image_size, camera=args.camera)
    success = bool(episode["next", "success"].any())
    print(f"expert episode: {len(episode)} steps, success {success}")
    if success:
        index = first_success_index(episode)
        goal_path = output_dir / f"{task.name}_expert_goal.png"
        Image.fromarray(episode["next", "pixels"][index].numpy()).save(goal_path)
        print(f"first success at step {index}; saved the goal frame to {goal_path}")


if __name__ == "__main__":
    main()
