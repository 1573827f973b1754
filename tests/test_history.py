"""EmbeddingHistoryTransform: s_0 and s_{t-k} per step, per episode, per batch element."""

import pytest
import torch
from rewards_mock_env import EmbeddingMockEnv, mock_embedding
from tensordict import TensorDict
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.data import episode_history
from temporal_torchrl.transforms import EmbeddingHistoryTransform

ELEMENT, EPISODE, STEP = 0, 1, 2  # channels of the mock embedding


def _history_env(k, episode_lengths, dim=6, window_length=None):
    return TransformedEnv(EmbeddingMockEnv(dim, episode_lengths),
                          EmbeddingHistoryTransform(k, window_length=window_length))


@pytest.mark.parametrize("episode_lengths", [(7,), (3, 5, 8)])
@pytest.mark.parametrize("window_length", [None, 4])
def test_specs_check(episode_lengths, window_length):
    env = _history_env(2, episode_lengths, window_length=window_length)
    check_env_specs(env)
    spec = env.observation_spec
    assert spec["previous_embedding"].shape == spec["embedding"].shape
    assert spec["initial_embedding"].dtype == torch.float32
    assert ("embedding_window" in spec.keys()) == (window_length is not None)
    if window_length:
        assert spec["embedding_window"].shape == (*spec["embedding"].shape[:-1], 4, 6)


@pytest.mark.parametrize(("k", "window_length"), [(2, 4), (6, 3), (1, 9)])
def test_window_across_episodes_never_crosses_a_start(k, window_length):
    """s_(t-K+1) .. s_t, padded with the episode's s_0 at its start (episodes of 4 steps: the
    window reaches past the start at every step when K = 9), next to the same s_(t-k) as
    without a window, whichever of k and K - 1 is larger."""
    env = _history_env(k, (4,), window_length=window_length)
    rollout = env.rollout(13, break_when_any_done=False)
    nxt = rollout["next"]
    for i in range(len(rollout)):
        t, episode = int(nxt["embedding"][i, STEP]), int(nxt["embedding"][i, EPISODE])
        expected = torch.stack([mock_embedding(0, episode, max(t - j, 0), 6)
                                for j in range(window_length - 1, -1, -1)])
        torch.testing.assert_close(nxt["embedding_window"][i], expected)
        torch.testing.assert_close(nxt["previous_embedding"][i],
                                   mock_embedding(0, episode, max(t - k, 0), 6))
    # At the reset frame the window is s_0 repeated; one episode's history is episode_history's
    # (the arithmetic the replay and the reports use).
    starts = rollout["embedding"][:, STEP] == 0
    torch.testing.assert_close(rollout["embedding_window"][starts],
                               rollout["embedding"][starts].unsqueeze(1).expand(-1,
                                                                               window_length, -1))
    first = torch.cat([rollout["embedding"][:1], nxt["embedding"][:4]])
    history = episode_history(first, k, window_length)
    torch.testing.assert_close(history["window"], torch.cat([rollout["embedding_window"][:1],
                                                             nxt["embedding_window"][:4]]))
    torch.testing.assert_close(history["previous"],
                               torch.cat([rollout["previous_embedding"][:1],
                                          nxt["previous_embedding"][:4]]))


def test_batched_windows_restart_only_the_reset_elements():
    env = _history_env(1, (3, 5, 8), window_length=3)
    nxt = env.rollout(17, break_when_any_done=False)["next"]
    for element in range(3):
        for i in range(17):
            episode = int(nxt["embedding"][element, i, EPISODE])
            t = int(nxt["embedding"][element, i, STEP])
            window = nxt["embedding_window"][element, i]
            assert window[:, ELEMENT].tolist() == [element] * 3
            assert window[:, EPISODE].tolist() == [episode] * 3
            assert window[:, STEP].tolist() == [max(t - 2, 0), max(t - 1, 0), t]


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
    history = EmbeddingHistoryTransform(k=1, window_length=2)
    first = history._reset(TensorDict(), TensorDict({"embedding": torch.zeros(2)}))
    history._step(TensorDict(), TensorDict({"embedding": torch.ones(2)}))
    history._step(TensorDict(), TensorDict({"embedding": torch.full((2,), 2.0)}))
    assert first["previous_embedding"].tolist() == [0.0, 0.0]
    assert first["initial_embedding"].tolist() == [0.0, 0.0]
    assert first["embedding_window"].tolist() == [[0.0, 0.0], [0.0, 0.0]]


def test_errors():
    with pytest.raises(ValueError, match="k=0"):
        EmbeddingHistoryTransform(k=0)
    with pytest.raises(ValueError, match="window_length=1"):
        EmbeddingHistoryTransform(window_length=1)
    with pytest.raises(ValueError, match="window_length=1"):
        episode_history(torch.zeros(3, 2), k=1, window_length=1)
    history = EmbeddingHistoryTransform()
    with pytest.raises(RuntimeError, match="reset"):
        history._step(TensorDict(), TensorDict({"embedding": torch.zeros(3)}))
    with pytest.raises(RuntimeError, match="stateful"):
        history(TensorDict({"embedding": torch.zeros(3)}))
    with pytest.raises(KeyError, match="embedding transform before"):
        history._reset(TensorDict(), TensorDict({"pixels": torch.zeros(3)}))


def _walk(history, steps, start=0.0):
    """Reset at ``start`` then ``steps`` steps of embeddings start+1, start+2, ...: the last
    step's outputs."""
    history._reset(TensorDict(), TensorDict({"embedding": torch.full((3,), start)}))
    return _steps(history, steps, start)


def _steps(history, steps, start):
    out = None
    for t in range(1, steps + 1):
        out = history._step(TensorDict(), TensorDict({"embedding": torch.full((3,), start + t)}))
    return {key: out[key].clone() for key in ("initial_embedding", "previous_embedding",
                                               "embedding_window")}


def test_state_dict_clone_and_to_carry_the_ring_mid_episode():
    # As CatFrames' buffer: a transform saved, cloned or moved mid-episode goes on where it was.
    original = EmbeddingHistoryTransform(k=2, window_length=3)
    _walk(original, 4)
    assert set(original.state_dict()) == {"_ring", "_initial", "_cursor"}
    restored = EmbeddingHistoryTransform(k=2, window_length=3)
    assert set(restored.state_dict()) == {"_cursor"}  # no ring before its first reset
    restored.load_state_dict(original.state_dict())
    clone = original.clone()
    expected = _steps(original, 3, 4.0)  # s_7: s_5 two back, s_0 the start, window s_5..s_7
    assert expected["previous_embedding"].tolist() == [5.0] * 3
    for other in (restored, clone):
        for key, value in _steps(other, 3, 4.0).items():
            assert torch.equal(value, expected[key]), key
    _steps(clone, 2, 100.0)  # the clone's ring is its own
    assert _steps(original, 1, 7.0)["previous_embedding"].tolist() == [6.0] * 3
    moved = original.to(torch.float64)
    assert moved._ring.dtype == moved._initial.dtype == torch.float64
    assert moved._cursor.dtype == torch.int64
