"""The canonical temporal env (render -> embed -> history -> reward) and its reward, composed.

:func:`make_temporal_reward` builds the :class:`~temporal_torchrl.rewards.TemporalReward` of a
task with the goal and baseline texts embedded by the encoder's text side;
:func:`make_temporal_env` stacks the four transforms on the task's env in the order the rewards
need them. Both are what ``recipes/sac_temporal.py`` runs; compose the transforms by hand (see
the README) to change the order or add your own.
"""

from __future__ import annotations

import functools
import os
from typing import Any

import torch
from tensordict import TensorDict
from torchrl.envs import EnvBase, ParallelEnv, TransformedEnv

from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs.experts import collect_expert_episodes
from temporal_torchrl.envs.metaworld_env import make_env
from temporal_torchrl.envs.tasks import GENERIC_BASELINE, get_task
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.transforms import (
    EmbeddingHistoryTransform,
    EmbeddingTransform,
    TemporalRewardTransform,
)

#: Expert episodes get the protocol's full episode length to succeed, however short training's.
EXPERT_MAX_STEPS = 500


def baseline_text(task: str, baseline: str = "generic") -> str:
    """``generic`` -> the generic baseline, ``tailored`` -> the task's own, any other text as is.

    >>> baseline_text("drawer-open") == GENERIC_BASELINE
    True
    """
    if not isinstance(baseline, str) or not baseline.strip():
        raise ValueError(f"baseline={baseline!r}; expected 'generic', 'tailored' or a text.")
    if baseline == "generic":
        return GENERIC_BASELINE
    if baseline == "tailored":
        tailored = get_task(task).tailored_baseline
        if tailored is None:
            raise ValueError(f"baseline='tailored': {task} has no tailored baseline (only the "
                             "thesis's six evaluation tasks have one); use 'generic' or a text.")
        return tailored
    return baseline


def make_temporal_reward(task: str, encoder: Encoder, *, positional: str | None = "furl",
                         directional: str | None = "d3", baseline: str = "generic",
                         **reward_options: Any) -> TemporalReward:
    """The temporal reward of ``task``, with goal and baseline texts embedded by ``encoder``.

    Args:
        task: the task whose goal prompt (:func:`~temporal_torchrl.envs.get_task`) is g.
        encoder: its text side embeds the goal prompt and the baseline.
        positional, directional: the reward names (None: that part is off).
        baseline: ``generic``, ``tailored`` (the task's own, thesis 4.2.2) or any text.
        **reward_options: :class:`~temporal_torchrl.rewards.TemporalReward`'s other arguments
            (``rho``, ``lambda_``, ``k``, ``alpha``, ``projection``, ``window_length``, ...).

    Example:
        >>> from temporal_torchrl.encoders import load_encoder
        >>> encoder = load_encoder("metaworld_small")
        >>> reward = make_temporal_reward("drawer-open", encoder, rho=1.0, lambda_=4.0)
        >>> reward.positional, reward.directional
        ('furl', 'd3')
    """
    texts = encoder.embed_text([get_task(task).goal_prompt, baseline_text(task, baseline)])
    return TemporalReward(encoder.dim, texts[0].float().cpu(), texts[1].float().cpu(),
                          positional=positional, directional=directional, **reward_options)


def make_temporal_env(task: str, seed: int = 0, *, encoder: Encoder | None = None,
                      reward: TemporalReward | None = None, history: int | None = None,
                      image_size: int = 224, camera: str = "corner2", fast_render: bool = True,
                      max_episode_steps: int = 500, num_envs: int = 1) -> EnvBase:
    """``task``'s env -> (render) -> embedding -> history -> temporal reward.

    Frames are rendered only when ``encoder`` reads pixels; without an encoder the plain task
    env (sparse reward) is returned. The history transform keeps s_0 and s_{t-k}, ``k`` from
    ``reward`` (or ``history`` without one), and the window a d_sequence reward reads.

    With ``num_envs`` > 1 the task (same layout) runs in that many worker processes
    (:class:`~torchrl.envs.ParallelEnv`, one torch thread and cores / N rasteriser threads
    each), each rendering its own frames;
    the embedding, history and reward transforms sit on the batched env, so one encoder forward
    embeds all N frames of a step, and partial resets restart only the envs that ended.

    Args:
        task, seed: the fixed-goal task and its layout (:func:`~temporal_torchrl.envs.make_env`).
        encoder: embeds each state into ``"embedding"``; None: no VLM transforms.
        reward: appended as a :class:`~temporal_torchrl.transforms.TemporalRewardTransform`;
            None: the env stops at the history (embeddings only).
        history: k when there is no reward (default 5).
        image_size, camera, fast_render, max_episode_steps: as in
            :func:`~temporal_torchrl.envs.make_env`.
        num_envs: copies of the task stepped in parallel (batch size ``[num_envs]``); 1: a
            single env with batch size ``[]``.

    Example:
        >>> from temporal_torchrl.encoders import load_encoder
        >>> encoder = load_encoder("metaworld_small")
        >>> reward = make_temporal_reward("drawer-open", encoder, rho=1.0, lambda_=4.0)
        >>> env = make_temporal_env("drawer-open", encoder=encoder, reward=reward,
        ...                         image_size=64, max_episode_steps=5)
        >>> rollout = env.rollout(5)
        >>> rollout["next", "vlm_reward"].shape, "pixels" in rollout.keys()
        (torch.Size([5, 1]), False)
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs={num_envs!r}; expected an integer >= 1.")
    render = encoder is not None and encoder.input_key == "pixels"
    if render:
        encoder.check_frame_size(image_size)
    settings = {"render": render, "image_size": image_size, "camera": camera,
                "fast_render": fast_render, "max_episode_steps": max_episode_steps}
    if num_envs == 1:
        env = make_env(task, seed, **settings)
    else:
        rasteriser_threads = max(1, (os.cpu_count() or 1) // num_envs)
        # The collector steps the workers and then updates, never both at once: this process
        # keeps its torch threads for the updates (ParallelEnv would give it cores - workers).
        env = ParallelEnv(num_envs, functools.partial(_worker_env, task, seed,
                                                      rasteriser_threads, **settings),
                          num_threads=torch.get_num_threads())
    if encoder is None:
        return env
    if not isinstance(env, TransformedEnv):
        env = TransformedEnv(env)
    env.append_transform(EmbeddingTransform(encoder))
    k = reward.k if reward is not None else (history or 5)
    window = reward.window_length if reward is not None else None
    env.append_transform(EmbeddingHistoryTransform(k=k, window_length=window))
    if reward is not None:
        env.append_transform(TemporalRewardTransform(reward))
    return env


def _worker_env(task: str, seed: int, rasteriser_threads: int, **settings: Any) -> EnvBase:
    """A ParallelEnv worker's env. Its software rasteriser (Mesa llvmpipe, before any GL
    context exists) gets its share of the cores, so N rendering workers do not oversubscribe
    them; its torch threads are set by ParallelEnv (one each)."""
    os.environ["LP_NUM_THREADS"] = str(rasteriser_threads)
    return make_env(task, seed, **settings)


def collect_successful_experts(task: str, seed: int, count: int, *, render: bool = False,
                               image_size: int = 224, camera: str = "corner2",
                               fast_render: bool = True,
                               max_episode_steps: int = EXPERT_MAX_STEPS,
                               steps_after_success: int | None = 5,
                               max_attempts: int = 5) -> list[TensorDict]:
    """``count`` successful scripted-expert episodes of the task's layout ``seed``.

    Episodes are cut ``steps_after_success`` steps after their first success (None: whole
    episodes). Noisy episodes that fail are replaced (new noise seeds), up to ``max_attempts``
    rounds; frames are rendered when ``render`` (pass the training run's render settings),
    nothing is embedded here.
    """
    episodes: list[TensorDict] = []
    for attempt in range(max_attempts):
        batch = collect_expert_episodes(
            task, seed, num_episodes=count - len(episodes), render=render,
            image_size=image_size, camera=camera, fast_render=fast_render,
            max_episode_steps=max_episode_steps, steps_after_success=steps_after_success,
            generator_seed=None if attempt == 0 else seed + 1000 * attempt)
        episodes += [episode for episode in batch if bool(episode["next", "success"].any())]
        if len(episodes) == count:
            return episodes
    raise RuntimeError(f"the scripted expert of {task} succeeded in only {len(episodes)} of the "
                       f"{count} episodes asked for in {max_attempts} rounds.")


