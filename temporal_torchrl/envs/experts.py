"""Scripted-expert episodes in the env's own TensorDict layout.

They are the stage-2 preloaded positives (thesis chapter 5: 50 positive episodes before training)
and the source of the goal image s_g (the first success frame), so they are collected through
:func:`~temporal_torchrl.envs.make_env` with the caller's render settings: their frames are the
frames training renders, pixel for pixel, from the same seed's layout.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs.utils import step_mdp

from temporal_torchrl import defaults
from temporal_torchrl.envs.metaworld_env import make_env
from temporal_torchrl.envs.tasks import TaskSpec, get_task
from temporal_torchrl.params import EnvParams, env_params

_GOAL_SLICE = slice(36, 39)
#: A retry round's noise generator is seeded with seed + this * round (round 0: ``seed``).
_RETRY_SEED = 1_000


def collect_expert_episodes(env: str | TaskSpec | EnvParams, seed: int | None = None,
                            num_episodes: int = 1, noise: float = defaults.EXPERT_NOISE,
                            render: bool = False, image_size: int | None = None,
                            camera: str | None = None, fast_render: bool | None = None,
                            steps_after_success: int | None = defaults.EXPERT_STEPS_AFTER_SUCCESS,
                            max_episode_steps: int | None = None,
                            generator_seed: int | None = None, goal: str | None = None,
                            stream_index: int = 0) -> list[TensorDict]:
    """Run Metaworld's scripted policy on the task (fixed goal and goal-hidden by default).

    Each action is the expert's action plus Gaussian noise, a = clip(pi(o) + noise * eps, -1, 1)
    with eps ~ N(0, I): with a fixed goal and no noise every episode would be identical.
    The expert reads the goal from ``obs[36:39]``, which the goal-hidden env zeroes, so the true
    goal of the layout is written into the expert's copy of the observation (the push expert
    never succeeds otherwise); the stored observations stay goal-hidden, as in training.

    An episode is cut ``steps_after_success`` steps after its first success (Metaworld experts
    can lose the success again later: door-open and push do); its last step is then marked
    ``truncated`` and ``done`` so episode boundaries stay visible in a replay buffer. With
    ``steps_after_success=None``, and for an episode with no success, the episode runs to
    ``max_episode_steps`` and ends truncated, as any env episode does.

    Args:
        env: the training run's :class:`~temporal_torchrl.params.EnvParams` (its layout, frames
            and goal setting, so the frames match the training frames), or a task name.
        seed, image_size, camera, fast_render, max_episode_steps, goal: override ``env``'s, as
            in :func:`make_env`; ``max_episode_steps`` is the length of an episode with no
            success.
        num_episodes: number of episodes.
        noise: standard deviation of the action noise.
        render: render ``"pixels"`` (:func:`make_env`).
        steps_after_success: steps kept after the first success; ``None`` keeps the whole
            episode.
        generator_seed: seed of the noise generator; ``None`` derives it from the seed, so the
            same call returns the same episodes.
        stream_index: with ``goal="random"`` each episode is on a new layout from the seed's
            ``"experts"`` stream, this index of it (of
            :func:`~temporal_torchrl.envs.metaworld_env.layout_generator`), never the
            training's or the evaluation's layouts.

    Returns:
        One TensorDict [T] per episode, in the layout ``env.rollout()`` gives (root keys at step
        t, the step's results under ``"next"``; ``"pixels"`` included when rendering).

    Example:
        >>> from temporal_torchrl.envs import collect_expert_episodes, first_success_index
        >>> episode, = collect_expert_episodes("button-press-topdown", seed=0)
        >>> bool(episode["next", "success"].any()), len(episode) == first_success_index(episode) + 6
        (True, True)
    """
    params = env_params(env.name if isinstance(env, TaskSpec) else env, seed,
                        image_size=image_size, camera=camera, fast_render=fast_render,
                        max_episode_steps=max_episode_steps, goal=goal)
    spec = get_task(params.task)
    if num_episodes < 0 or noise < 0 or (steps_after_success or 0) < 0:
        raise ValueError(
            f"num_episodes={num_episodes}, noise={noise}, steps_after_success="
            f"{steps_after_success}: all three must be non-negative (steps_after_success may "
            "also be None, for whole episodes)."
        )
    env = make_env(params, render=render, stream="experts", stream_index=stream_index)
    base_env = getattr(env, "base_env", env)
    rng = np.random.default_rng(params.seed if generator_seed is None else generator_seed)
    episodes = []
    try:
        for _ in range(num_episodes):
            expert = spec.make_expert()
            tensordict = env.reset()
            true_goal = base_env.goal_position  # read after the reset that drew the layout
            steps, first_success = [], None
            for t in range(params.max_episode_steps):
                observation = tensordict["observation"].numpy().astype(np.float64)
                observation[_GOAL_SLICE] = true_goal
                with warnings.catch_warnings():
                    # Metaworld's policies warn whenever their gains exceed the action range,
                    # which the clip below handles.
                    warnings.filterwarnings("ignore", "Constant", UserWarning)
                    action = expert.get_action(observation)
                action = action + noise * rng.standard_normal(4)
                tensordict["action"] = torch.as_tensor(np.clip(action, -1.0, 1.0),
                                                       dtype=torch.float32)
                tensordict = env.step(tensordict)
                steps.append(tensordict)
                if first_success is None and tensordict["next", "success"].item():
                    first_success = t
                if tensordict["next", "done"].item():
                    break
                if (steps_after_success is not None and first_success is not None
                        and t >= first_success + steps_after_success):
                    tensordict["next", "truncated"] = torch.ones(1, dtype=torch.bool)
                    tensordict["next", "done"] = torch.ones(1, dtype=torch.bool)
                    break
                tensordict = step_mdp(tensordict)
            episodes.append(torch.stack(steps))
    finally:
        env.close()
    return episodes


def first_success_index(episode: TensorDict) -> int:
    """Index t of the first step whose ``("next", "success")`` is True.

    ``episode["next", "pixels"][t]`` is then the first success frame (the goal image).

    Raises:
        ValueError: when the episode never succeeds.
    """
    success = episode["next", "success"].reshape(len(episode), -1).any(-1)
    if not success.any():
        raise ValueError(
            f"This episode of {len(episode)} steps never succeeds: keep only successful episodes "
            "(episode['next', 'success'].any()) before asking for the first success."
        )
    return int(success.nonzero()[0, 0])


def collect_successful_experts(
        env: str | EnvParams, count: int, *, noise: float = defaults.EXPERT_NOISE,
        render: bool = False,
        steps_after_success: int | None = defaults.EXPERT_STEPS_AFTER_SUCCESS,
        max_attempts: int = 5) -> list[TensorDict]:
    """``count`` successful scripted-expert episodes of ``env``'s task and layout (random
    goals: of layouts from the seed's experts stream), the stage-2 preloaded positives and the
    reward-quality benchmark's alike.

    Episodes are cut ``steps_after_success`` steps after their first success (None: whole
    episodes). A noisy episode that fails is replaced in the next round, with a new noise seed
    and, for random goals, new layouts; up to ``max_attempts`` episodes are tried per episode
    wanted. Frames are rendered when ``render`` (``env`` holds the training run's render
    settings), nothing is embedded here.

    Raises:
        RuntimeError: when fewer than ``count`` of the episodes tried succeed.
    """
    params = env_params(env)
    episodes: list[TensorDict] = []
    tried = attempt = 0
    while len(episodes) < count:
        if tried >= max_attempts * count:
            raise RuntimeError(
                f"the scripted expert of {params.task} (noise {noise}) succeeded in only "
                f"{len(episodes)} of {tried} episodes, {count} wanted: lower the noise or raise "
                "max_attempts.")
        missing = count - len(episodes)
        batch = collect_expert_episodes(
            params, num_episodes=missing, noise=noise, render=render,
            steps_after_success=steps_after_success,
            generator_seed=None if attempt == 0 else params.seed + _RETRY_SEED * attempt,
            stream_index=attempt)
        episodes += [episode for episode in batch if bool(episode["next", "success"].any())]
        tried, attempt = tried + missing, attempt + 1
    return episodes
