"""The canonical temporal env: render -> embed -> history -> reward, composed.

:func:`make_temporal_env` stacks the four transforms on the task's env in the order the rewards
need them (the reward from :func:`~temporal_torchrl.envs.make_temporal_reward`). It is what
``recipes/sac_temporal.py`` runs; compose the transforms by hand (``docs/guides/composing.md``)
to change the order or add your own.
"""

from __future__ import annotations

import functools
import os

import torch
from torchrl.envs import EnvBase, ParallelEnv, TransformedEnv

from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs.metaworld_env import make_env
from temporal_torchrl.params import EnvParams, env_params
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.rewards.temporal import renamed_k, resolve_k
from temporal_torchrl.transforms import (
    EmbeddingHistoryTransform,
    EmbeddingTransform,
    TemporalRewardTransform,
)


def make_temporal_env(env: str | EnvParams, seed: int | None = None, *,
                      encoder: Encoder | None = None, reward: TemporalReward | None = None,
                      k: int | None = None, image_size: int | None = None,
                      camera: str | None = None, fast_render: bool | None = None,
                      max_episode_steps: int | None = None, num_envs: int = 1,
                      goal: str | None = None, history: int | None = None) -> EnvBase:
    """``task``'s env -> (render) -> embedding -> history -> temporal reward.

    Frames are rendered only when ``encoder`` reads pixels; without an encoder the plain task
    env (sparse reward) is returned. The history transform keeps s_0 and s_{t-k}, ``k`` from
    ``reward`` (or ``k`` without one), and the window a d_sequence reward reads.

    With ``num_envs`` > 1 the task (fixed goal: the same layout; random goal: each worker its
    own layout stream, so no two workers share layouts) runs in that many worker processes
    (:class:`~torchrl.envs.ParallelEnv`, one torch thread and cores / N rasteriser threads
    each), each rendering its own frames;
    the embedding, history and reward transforms sit on the batched env, so one encoder forward
    embeds all N frames of a step, and partial resets restart only the envs that ended.

    Args:
        env: the task's :class:`~temporal_torchrl.params.EnvParams` (its layout, episode length,
            goal setting and frames), or a task name with those at their defaults.
        seed, image_size, camera, fast_render, max_episode_steps, goal: override ``env``'s
            (None: keep it), as in :func:`~temporal_torchrl.envs.make_env`.
        encoder: embeds each state into ``"embedding"``; None: no VLM transforms.
        reward: appended as a :class:`~temporal_torchrl.transforms.TemporalRewardTransform`;
            None: the env stops at the history (embeddings only).
        k: the offset of s_(t-k) when there is no reward (default
            :data:`~temporal_torchrl.defaults.K`); with a reward, k is the reward's ``k`` and a
            different one is refused.
        num_envs: copies of the task stepped in parallel (batch size ``[num_envs]``); 1: a
            single env with batch size ``[]``.
        history: the deprecated name of ``k`` (a FutureWarning; removed in the next release).

    Example:
        >>> from temporal_torchrl.encoders import load_encoder
        >>> from temporal_torchrl.envs import make_temporal_reward
        >>> encoder = load_encoder("metaworld_small")
        >>> from temporal_torchrl.params import EnvParams
        >>> reward = make_temporal_reward("drawer-open", encoder, rho=1.0, lambda_=4.0)
        >>> env = make_temporal_env(EnvParams("drawer-open", max_episode_steps=5),
        ...                         encoder=encoder, reward=reward)
        >>> rollout = env.rollout(5)
        >>> rollout["next", "vlm_reward"].shape, "pixels" in rollout.keys()
        (torch.Size([5, 1]), False)
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs={num_envs!r}; expected an integer >= 1.")
    # refused before any env is built
    k = resolve_k(renamed_k(k, history, "make_temporal_env"), reward, "make_temporal_env")
    params = env_params(env, seed, image_size=image_size, camera=camera,
                        fast_render=fast_render, max_episode_steps=max_episode_steps, goal=goal)
    render = encoder is not None and encoder.input_key == "pixels"
    if render:
        encoder.check_frame_size(params.image_size)
    if num_envs == 1:
        env = make_env(params, render=render)
    else:
        rasteriser_threads = max(1, (os.cpu_count() or 1) // num_envs)
        # The collector steps the workers and then updates, never both at once: this process
        # keeps its torch threads for the updates (ParallelEnv would give it cores - workers).
        # One env function (a single task for TorchRL); each worker's own layout stream comes
        # with its kwargs.
        env = ParallelEnv(num_envs, functools.partial(_worker_env, params, render,
                                                      rasteriser_threads),
                          create_env_kwargs=[{"stream_index": index} for index in range(num_envs)],
                          num_threads=torch.get_num_threads())
    if encoder is None:
        return env
    if not isinstance(env, TransformedEnv):
        env = TransformedEnv(env)
    env.append_transform(EmbeddingTransform(encoder))
    window = reward.window_length if reward is not None else None
    env.append_transform(EmbeddingHistoryTransform(k=k, window_length=window))
    if reward is not None:
        env.append_transform(TemporalRewardTransform(reward))
    return env


def _worker_env(params: EnvParams, render: bool, rasteriser_threads: int,
                stream_index: int) -> EnvBase:
    """A ParallelEnv worker's env. Its software rasteriser (Mesa llvmpipe, before any GL
    context exists) gets its share of the cores, so N rendering workers do not oversubscribe
    them; its torch threads are set by ParallelEnv (one each)."""
    os.environ["LP_NUM_THREADS"] = str(rasteriser_threads)
    return make_env(params, render=render, stream_index=stream_index)
