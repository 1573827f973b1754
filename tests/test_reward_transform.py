"""TemporalRewardTransform: the env path and the replay (relabelling) path agree."""

import pytest
import torch
from rewards_mock_env import EmbeddingMockEnv
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.envs import Compose, FrameSkipTransform, RewardSum, TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.envs import make_env
from temporal_torchrl.rewards import REWARD_KEYS, TemporalReward
from temporal_torchrl.transforms import (
    EmbeddingHistoryTransform,
    EmbeddingTransform,
    TemporalRewardTransform,
)

D = 6


def _reward(**kwargs):
    gen = torch.Generator().manual_seed(5)
    defaults = {"positional": "furl", "directional": "d3", "rho": 1.0, "lambda_": 4.0, "k": 2}
    return TemporalReward(D, torch.randn(D, generator=gen), torch.randn(D, generator=gen),
                          **{**defaults, **kwargs})


def _env(reward, episode_lengths=(3, 5, 8)):
    return TransformedEnv(EmbeddingMockEnv(D, episode_lengths),
                          Compose(EmbeddingHistoryTransform(reward.k,
                                                            window_length=reward.window_length),
                                  TemporalRewardTransform(reward)))


@pytest.mark.parametrize("episode_lengths", [(6,), (3, 5, 8)])
def test_specs_check(episode_lengths):
    env = _env(_reward(), episode_lengths)
    check_env_specs(env)
    # One reward, the shaped one, as TorchRL's losses, collectors and RewardSum expect; the
    # parts beside it as observations (0 at a reset, as RewardSum's episode sum).
    assert env.reward_keys == ["reward"] and env.reward_key == "reward"
    assert set(REWARD_KEYS) - {"reward"} <= set(env.observation_spec.keys())
    reset = env.reset()
    assert all(reset[key].eq(0).all() for key in REWARD_KEYS if key != "reward")


def test_torchrl_transforms_that_read_the_reward_key_work_after_it():
    reward = _reward()
    env = _env(reward, (4, 6))
    env.append_transform(RewardSum())
    check_env_specs(env)
    rollout = env.rollout(10, break_when_any_done=False)
    # RewardSum sums the shaped reward of each of the 2 envs, restarting at each one's own
    # auto-reset (episodes of 4 and of 6 steps)
    shaped = rollout["next", "reward"].squeeze(-1)
    summed = rollout["next", "episode_reward"].squeeze(-1)
    for env_index, start, end in ((0, 0, 4), (0, 4, 8), (1, 0, 6), (1, 6, 10)):
        torch.testing.assert_close(summed[env_index, end - 1],
                                   shaped[env_index, start:end].sum())
    skipping = _env(_reward(), (12,))
    skipping.append_transform(FrameSkipTransform(2))
    check_env_specs(skipping)
    assert skipping.rollout(3)["next", "reward"].shape == (3, 1)


@pytest.mark.parametrize(("positional", "directional"),
                         [("furl", "d3"), ("p1", "d4"), ("p3", "d5"), (None, "d2"), ("liv", None),
                          ("furl", "d_sequence"), (None, "d_certainty")])
def test_env_reward_equals_relabelled_stored_batch(positional, directional):
    reward = _reward(positional=positional, directional=directional)
    rollout = _env(reward).rollout(12, break_when_any_done=False)
    collected = {key: rollout["next", key].clone() for key in REWARD_KEYS}
    stored = rollout.exclude(*[("next", key) for key in REWARD_KEYS])
    relabelled = TemporalRewardTransform(reward)(stored)
    for key in REWARD_KEYS:
        torch.testing.assert_close(relabelled["next", key], collected[key])
    # The env's sparse reward was overwritten: r_task + rho * vlm, not success - 1.
    success = rollout["next", "success"].float()
    torch.testing.assert_close(collected["task_reward"], success - 1)
    torch.testing.assert_close(collected["reward"],
                               success - 1 + reward.rho * collected["vlm_reward"])
    assert not torch.equal(collected["reward"], success - 1)


def test_relabelling_uses_the_heads_as_they_are_now():
    reward = _reward()
    transform = TemporalRewardTransform(reward)
    rollout = _env(reward).rollout(10, break_when_any_done=False)
    before = rollout["next", "reward"].clone()
    with torch.no_grad():
        for parameter in reward.directional_heads.parameters():
            parameter.add_(0.5 * torch.randn_like(parameter))
    after = transform(rollout.clone())["next", "reward"]
    assert not torch.allclose(after, before)
    nxt = rollout["next"]
    expected = reward(nxt["embedding"], nxt["initial_embedding"], nxt["previous_embedding"],
                      nxt["success"])["reward"]
    torch.testing.assert_close(after, expected)
    assert not after.requires_grad


def test_replay_buffer_transform_relabels_sampled_transitions():
    reward = _reward()
    rollout = _env(reward).rollout(10, break_when_any_done=False).reshape(-1)
    buffer = ReplayBuffer(storage=LazyTensorStorage(100), batch_size=8,
                          transform=TemporalRewardTransform(reward))
    buffer.extend(rollout.exclude(("next", "reward")))
    batch = buffer.sample()
    nxt = batch["next"]
    expected = reward(nxt["embedding"], nxt["initial_embedding"], nxt["previous_embedding"],
                      nxt["success"])["reward"]
    torch.testing.assert_close(nxt["reward"], expected)


def test_flat_tensordict_is_relabelled_at_the_root():
    reward = _reward()
    s = torch.randn(3, D)
    flat = TensorDict({"embedding": s, "initial_embedding": s, "previous_embedding": s,
                       "success": torch.ones(3, 1, dtype=torch.bool)}, [3])
    out = TemporalRewardTransform(reward)(flat)
    assert torch.equal(out["task_reward"], torch.zeros(3, 1))


def test_rejects_something_else_than_a_temporal_reward():
    with pytest.raises(ValueError, match="expected a TemporalReward"):
        TemporalRewardTransform(torch.nn.Identity())


def test_missing_history_is_explained():
    s = torch.randn(3, D)
    flat = TensorDict({"embedding": s, "success": torch.ones(3, 1, dtype=torch.bool)}, [3])
    with pytest.raises(KeyError, match="initial_embedding.*EmbeddingHistoryTransform"):
        TemporalRewardTransform(_reward())(flat)


def test_missing_window_is_explained():
    s = torch.randn(3, D)
    flat = TensorDict({"embedding": s, "initial_embedding": s, "previous_embedding": s,
                       "success": torch.ones(3, 1, dtype=torch.bool)}, [3])
    with pytest.raises(KeyError, match=r"embedding_window.*window_length=8\)"):
        TemporalRewardTransform(_reward(directional="d_sequence"))(flat)


def test_mismatching_embedding_size_in_the_env_is_explained():
    reward = TemporalReward(D + 2, torch.randn(D + 2), torch.randn(D + 2), directional="d3")
    env = _env(reward)
    env.reset()
    with pytest.raises(ValueError, match=f"size {D}.*embedding_dim={D + 2}"):
        env.rand_step()


def test_real_env_and_state_encoder_pass_check_env_specs():
    encoder = load_encoder("state")
    gen = torch.Generator().manual_seed(0)
    reward = TemporalReward(encoder.dim, torch.randn(encoder.dim, generator=gen),
                            torch.randn(encoder.dim, generator=gen), directional="d3", k=3)
    env = TransformedEnv(make_env("drawer-open", max_episode_steps=12),
                         Compose(EmbeddingTransform(encoder), EmbeddingHistoryTransform(reward.k),
                                 TemporalRewardTransform(reward)))
    check_env_specs(env)
    rollout = env.rollout(15, break_when_any_done=False)
    relabelled = TemporalRewardTransform(reward)(rollout.clone())
    torch.testing.assert_close(relabelled["next", "reward"], rollout["next", "reward"])


def test_the_envs_state_dict_holds_the_heads_and_restores_them():
    # The heads are referenced, not registered (env.to() must not move them), yet an env
    # checkpointed alone, as TorchRL users do, keeps them.
    trained, fresh = _reward(), _reward()
    with torch.no_grad():
        for parameter in trained.parameters():
            parameter.add_(torch.randn_like(parameter))
    state = _env(trained).state_dict()
    keys = {key for key in state if ".reward." in key}
    assert keys == {f"transforms.1.reward.{key}" for key in trained.state_dict()}
    env = _env(fresh)
    env.load_state_dict(state)  # strict: no key missing or unexpected
    for key, value in trained.state_dict().items():
        assert torch.equal(fresh.state_dict()[key], value), key
    rollout = env.rollout(6, break_when_any_done=False)
    expected = _env(trained).rollout(6, break_when_any_done=False)
    torch.testing.assert_close(rollout["next", "reward"], expected["next", "reward"])
    incomplete = {key: value for key, value in state.items() if "directional_heads" not in key}
    with pytest.raises(RuntimeError, match="Missing key.*directional_heads"):
        _env(_reward()).load_state_dict(incomplete)
