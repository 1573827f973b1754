"""The checks TorchRL's own test suite applies to every transform (``TransformBase`` in its
``test/test_transforms.py``), for each of the project's four: rendering, embedding, the k-step
history and the temporal reward.

Each transform runs over a real Metaworld env (the ``state`` encoder keeps it fast): spec checks
over a single env, inside the workers of a ``SerialEnv`` and on a batched env; called on a
tensordict without an env; inside ``Compose``; inside a model; appended to a replay buffer;
cloned. Where a check cannot apply, the test asserts the transform says so, and the reason is
written beside it. One ``ParallelEnv`` (spawned workers) runs the whole chain.
"""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.envs import Compose, ParallelEnv, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.envs.metaworld_env import MetaworldEnv
from temporal_torchrl.rewards import REWARD_KEYS, TemporalReward
from temporal_torchrl.transforms import (
    EmbeddingHistoryTransform,
    EmbeddingTransform,
    RenderTransform,
    TemporalRewardTransform,
)

D, STEPS, SIZE = 8, 4, 16
ENCODER = load_encoder("state", dim=D)
REWARD = TemporalReward(D, torch.randn(D, generator=torch.Generator().manual_seed(0)),
                        torch.randn(D, generator=torch.Generator().manual_seed(1)), k=2)


def base_env() -> MetaworldEnv:
    return MetaworldEnv("push", max_episode_steps=STEPS)


# Each transform with the env it needs under it (what its in_keys come from).
def render():
    return RenderTransform(image_size=SIZE)


def embedding():
    return EmbeddingTransform(ENCODER)


def history():
    return EmbeddingHistoryTransform(k=2)


def reward():
    return TemporalRewardTransform(REWARD)


BELOW = {render: [], embedding: [], history: [embedding], reward: [embedding, history]}
TRANSFORMS = list(BELOW)


def env_with(make, *, base=base_env) -> TransformedEnv:
    return TransformedEnv(base(), Compose(*(below() for below in BELOW[make]), make()))


@pytest.mark.parametrize("make", TRANSFORMS, ids=lambda make: make.__name__)
def test_single_env(make):
    env = env_with(make)
    check_env_specs(env)
    # over an auto-reset in the middle: 2 episodes of STEPS and a third begun
    rollout = env.rollout(2 * STEPS + 2, break_when_any_done=False)
    assert rollout.shape == (2 * STEPS + 2,)
    for key in make().out_keys:
        assert ("next", key) in rollout.keys(True), key


@pytest.mark.parametrize("make", TRANSFORMS, ids=lambda make: make.__name__)
def test_in_the_workers_of_a_serial_env(make):
    check_env_specs(SerialEnv(2, lambda: env_with(make)))


@pytest.mark.parametrize("make", TRANSFORMS, ids=lambda make: make.__name__)
def test_on_a_batched_env(make):
    if make is render:
        # It renders from one simulator's MuJoCo model and data: it refuses a batched env,
        # saying to go inside each worker.
        with pytest.raises(ValueError, match="inside each worker of a batched env"):
            TransformedEnv(SerialEnv(2, base_env), render()).reset()
        return
    env = TransformedEnv(SerialEnv(2, base_env),
                         Compose(*(below() for below in BELOW[make]), make()))
    check_env_specs(env)
    rollout = env.rollout(STEPS + 2, break_when_any_done=False)
    assert rollout.shape == (2, STEPS + 2)


def test_the_history_restarts_at_an_auto_reset():
    env = env_with(history)
    rollout = env.rollout(STEPS + 3, break_when_any_done=False)
    embeddings = rollout["next", "embedding"]
    # step STEPS ended the first episode; the env reset in the rollout, so the next state's
    # s_0 is the new episode's first embedding (the root of step STEPS), not the old one's
    restart = rollout[STEPS]
    assert torch.equal(rollout["next", "initial_embedding"][STEPS], restart["embedding"])
    # s_{t-2} is clamped to s_0 in the new episode's first two steps, not carried over from
    # the old episode (whose s_{STEPS-1} the ring held two steps back)
    assert torch.equal(rollout["next", "previous_embedding"][STEPS], restart["embedding"])
    assert not torch.equal(rollout["next", "previous_embedding"][STEPS], embeddings[STEPS - 2])
    assert torch.equal(rollout["next", "previous_embedding"][STEPS + 2], embeddings[STEPS])


def _stored_batch() -> TensorDict:
    """Transitions as a replay buffer holds them: the env's keys, rewards recomputable."""
    return env_with(reward).rollout(STEPS, break_when_any_done=False)


@pytest.mark.parametrize("make", TRANSFORMS, ids=lambda make: make.__name__)
def test_without_an_env_in_compose_in_a_model_and_in_a_replay_buffer(make):
    batch = _stored_batch()
    if make is history:
        # Stateful, it runs only in an env: a stored batch already carries its keys as they
        # were collected. It says so wherever it is called on data.
        for call in (make(), Compose(make()), nn.Sequential(make())):
            with pytest.raises(RuntimeError, match="only runs inside an environment"):
                call(batch.clone())
        return
    expected = make()(batch.clone())
    if make is render:  # a frame can only come from a live simulator: the identity on data
        assert set(expected.keys(True)) == set(batch.keys(True))
    for call in (Compose(make()), nn.Sequential(make())):
        out = call(batch.clone())
        for key in expected.keys(True, True):
            torch.testing.assert_close(out[key], expected[key])
    buffer = ReplayBuffer(storage=LazyTensorStorage(2 * STEPS), batch_size=STEPS)
    buffer.append_transform(make())
    buffer.extend(batch.clone())
    sampled = buffer.sample()
    for key in make().out_keys if make is not render else ():
        assert ("next", key) in sampled.keys(True), key


def test_a_replay_buffer_transform_relabels_what_it_samples():
    batch = _stored_batch()
    stored = batch.exclude(*[("next", key) for key in REWARD_KEYS])
    buffer = ReplayBuffer(storage=LazyTensorStorage(STEPS), batch_size=STEPS)
    buffer.append_transform(reward())
    buffer.extend(stored)
    sampled = buffer.sample()
    expected = REWARD(*(sampled["next", key] for key in (
        "embedding", "initial_embedding", "previous_embedding", "success")))["reward"]
    torch.testing.assert_close(sampled["next", "reward"], expected)


@pytest.mark.parametrize("make", TRANSFORMS, ids=lambda make: make.__name__)
def test_a_clone_runs_on_its_own(make):
    original = env_with(make)
    original.rollout(2)
    clone = TransformedEnv(base_env(), Compose(*(below() for below in BELOW[make]),
                                                *[original.transform[-1].clone()]))
    check_env_specs(clone)
    original.rollout(2)  # the original goes on after its clone ran


@pytest.mark.slow
def test_the_whole_chain_in_spawned_parallel_workers():
    # Rendering and embedding inside each worker, the history and the reward on the outer env.
    def worker() -> TransformedEnv:
        return TransformedEnv(base_env(), Compose(render(), embedding()))

    env = TransformedEnv(ParallelEnv(2, worker, mp_start_method="spawn"),
                         Compose(history(), reward()))
    try:
        check_env_specs(env)
        rollout = env.rollout(STEPS + 1, break_when_any_done=False)
        assert rollout["next", "pixels"].shape == (2, STEPS + 1, SIZE, SIZE, 3)
        assert rollout["next", "reward"].shape == (2, STEPS + 1, 1)
    finally:
        env.close()
