"""EmbeddingHistoryTransform: s_0 and s_{t-k} per step, per episode, per batch element."""

import pytest
import torch
from rewards_mock_env import EmbeddingMockEnv, mock_embedding
from tensordict import TensorDict
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.transforms import EmbeddingHistoryTransform

ELEMENT, EPISODE, STEP = 0, 1, 2  # channels of the mock embedding


def _history_env(k, episode_lengths, dim=6):
    return TransformedEnv(EmbeddingMockEnv(dim, episode_lengths), EmbeddingHistoryTransform(k))


@pytest.mark.parametrize("episode_lengths", [(7,), (3, 5, 8)])
def test_specs_check(episode_lengths):
    env = _history_env(2, episode_lengths)
    check_env_specs(env)
    spec = env.observation_spec
    assert spec["previous_embedding"].shape == spec["embedding"].shape
    assert spec["initial_embedding"].dtype == torch.float32


@pytest.mark.parametrize("k", [1, 3, 10])
def test_single_env_matches_the_definition_across_episodes(k):
    # Episodes of 4 steps: with k = 10 the offset always exceeds the steps so far.
    env = _history_env(k, (4,))
    rollout = env.rollout(13, break_when_any_done=False)
    nxt = rollout["next"]
    steps, episodes = nxt["embedding"][:, STEP], nxt["embedding"][:, EPISODE]
    for i in range(len(rollout)):
        t, episode = int(steps[i]), int(episodes[i])
        expected_previous = mock_embedding(0, episode, max(t - k, 0), 6)
        torch.testing.assert_close(nxt["previous_embedding"][i], expected_previous)
        torch.testing.assert_close(nxt["initial_embedding"][i], mock_embedding(0, episode, 0, 6))
    # Root (time-t) entries: at every episode start s_{t-k} = s_0 = s_t.
    starts = rollout["embedding"][:, STEP] == 0
    assert starts.sum() == 4
    torch.testing.assert_close(rollout["previous_embedding"][starts], rollout["embedding"][starts])
    torch.testing.assert_close(rollout["initial_embedding"][starts], rollout["embedding"][starts])


def test_batched_env_partial_resets_restart_only_the_reset_elements():
    k = 2
    env = _history_env(k, (3, 5, 8))
    rollout = env.rollout(17, break_when_any_done=False)  # [3 elements, 17 steps]
    nxt = rollout["next"]
    assert nxt["done"].any(-1).any(-1).all(), "every element should finish at least one episode"
    for element in range(3):
        for i in range(17):
            episode = int(nxt["embedding"][element, i, EPISODE])
            t = int(nxt["embedding"][element, i, STEP])
            previous = nxt["previous_embedding"][element, i]
            assert int(previous[ELEMENT]) == element and int(previous[EPISODE]) == episode
            assert int(previous[STEP]) == max(t - k, 0)
            torch.testing.assert_close(nxt["initial_embedding"][element, i],
                                       mock_embedding(element, episode, 0, 6))


def test_outputs_do_not_alias_the_ring():
    history = EmbeddingHistoryTransform(k=1)
    first = history._reset(TensorDict(), TensorDict({"embedding": torch.zeros(2)}))
    history._step(TensorDict(), TensorDict({"embedding": torch.ones(2)}))
    history._step(TensorDict(), TensorDict({"embedding": torch.full((2,), 2.0)}))
    assert first["previous_embedding"].tolist() == [0.0, 0.0]
    assert first["initial_embedding"].tolist() == [0.0, 0.0]


def test_errors():
    with pytest.raises(ValueError, match="k=0"):
        EmbeddingHistoryTransform(k=0)
    history = EmbeddingHistoryTransform()
    with pytest.raises(RuntimeError, match="reset"):
        history._step(TensorDict(), TensorDict({"embedding": torch.zeros(3)}))
    with pytest.raises(RuntimeError, match="stateful"):
        history(TensorDict({"embedding": torch.zeros(3)}))
    with pytest.raises(KeyError, match="embedding transform before"):
        history._reset(TensorDict(), TensorDict({"pixels": torch.zeros(3)}))
