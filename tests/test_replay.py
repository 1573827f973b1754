"""Episode replay buffer: histories by index, boundaries, starts, overwrite, labels, memory."""

import pytest
import torch
from tensordict import TensorDict

from temporal_torchrl.data import (
    NEGATIVE,
    POSITIVE,
    EpisodeReplayBuffer,
    episode_labels,
    goal_image_embedding,
)
from temporal_torchrl.transforms import episode_windows

D = 4


def make_episode(episode: int, steps: int, successes=(), dim: int = D) -> TensorDict:
    """An episode whose state t has embedding and observation all equal to 100 * episode + t."""
    states = (100.0 * episode + torch.arange(steps + 1, dtype=torch.float32)).unsqueeze(-1)
    success = torch.zeros(steps + 1, 1, dtype=torch.bool)
    for t in successes:  # success after transition t
        success[t + 1] = True
    return TensorDict({
        "observation": states.expand(-1, 39)[:-1].clone(),
        "embedding": states.expand(-1, dim)[:-1].clone(),
        "action": torch.rand(steps, 4),
        "success": success[:-1],
        "next": {"observation": states.expand(-1, 39)[1:].clone(),
                 "embedding": states.expand(-1, dim)[1:].clone(),
                 "success": success[1:],
                 "terminated": torch.zeros(steps, 1, dtype=torch.bool)},
    }, [steps])


def marker(values: torch.Tensor) -> torch.Tensor:
    return values[..., 0]


def check_histories(buffer: EpisodeReplayBuffer, batch: TensorDict) -> None:
    k = buffer.history
    step, episode = batch["step"], batch["episode"]
    base = 100.0 * episode
    nxt = batch["next"]
    assert torch.equal(marker(nxt["embedding"]), base + step + 1)
    assert torch.equal(marker(nxt["observation"]), base + step + 1)
    assert torch.equal(marker(batch["observation"]), base + step)
    assert torch.equal(marker(nxt["initial_embedding"]), base)
    assert torch.equal(marker(nxt["previous_embedding"]),
                       base + torch.clamp(step + 1 - k, min=0))


def test_every_transition_with_histories_never_crossing_episodes():
    buffer = EpisodeReplayBuffer(capacity=200, history=3)
    for episode, steps in enumerate((7, 2, 12)):
        buffer.extend(make_episode(episode, steps))
    assert buffer.num_transitions == 7 + 2 + 12
    batch = buffer.transitions_at(buffer._transitions)
    check_histories(buffer, batch)
    # every step of every episode, starts included, is a sampleable transition
    pairs = set(zip(batch["episode"].tolist(), batch["step"].tolist(), strict=True))
    assert pairs == {(e, t) for e, n in enumerate((7, 2, 12)) for t in range(n)}
    last = batch["next", "truncated"].squeeze(-1)
    assert torch.equal(last, batch["step"] == torch.tensor([7, 2, 12])[batch["episode"]] - 1)
    assert not batch["next", "terminated"].any()
    sampled = buffer.sample(500)
    check_histories(buffer, sampled)
    assert (sampled["step"] == 0).any()
    assert sampled["next", "embedding"].dtype == torch.float32
    assert buffer._column("embedding").dtype == torch.float16


def test_windows_by_index_are_padded_at_starts_and_never_cross_episodes():
    """The window s_(t-K+1) .. s_t of every state (finetuning) and s_(t+2-K) .. s_(t+1) of every
    transition (relabelling), with a ring that wrapped: episode 2 went to rows 0..9 (episode 0
    overwritten), episode 1 sits at rows 12..22 after stale rows of episode 0, so a window
    reaching past a start would read another episode's marker (or the storage's last row)."""
    length = 4
    buffer = EpisodeReplayBuffer(capacity=24, history=2, window_length=length)
    for episode, steps in enumerate((11, 10, 9)):  # the third wraps to row 0
        buffer.extend(make_episode(episode, steps))
    assert buffer.num_episodes == 2
    batch = buffer.transitions_at(buffer._transitions)
    check_histories(buffer, batch)
    expected = (100.0 * batch["episode"].unsqueeze(-1) + torch.clamp(
        batch["step"].unsqueeze(-1) + 1 - torch.arange(length - 1, -1, -1), min=0))
    assert torch.equal(marker(batch["next", "embedding_window"]), expected)
    states = buffer.states_at(torch.arange(10))  # episode 2: s_0 .. s_9
    assert marker(states["embedding_window"]).tolist()[:4] == [
        [200.0] * 4, [200.0, 200.0, 200.0, 201.0], [200.0, 200.0, 201.0, 202.0],
        [200.0, 201.0, 202.0, 203.0]]
    assert torch.equal(states["embedding_window"], episode_windows(states["embedding"], length))
    finetuning = buffer.sample_finetuning(64)
    negatives = finetuning["negative"]
    assert torch.equal(marker(negatives["embedding_window"][:, -1]), marker(
        negatives["embedding"]))
    plain = EpisodeReplayBuffer(capacity=24, history=2)
    plain.extend(make_episode(0, 5))
    assert "embedding_window" not in plain.sample(4)["next"].keys()
    with pytest.raises(ValueError, match="window_length=1"):
        EpisodeReplayBuffer(capacity=24, window_length=1)


def test_overwrite_invalidates_whole_old_episodes():
    buffer = EpisodeReplayBuffer(capacity=30, history=2)
    buffer.extend(make_episode(0, 9))   # rows 0..9
    buffer.extend(make_episode(1, 9))   # rows 10..19
    buffer.extend(make_episode(2, 4))   # rows 20..24
    buffer.extend(make_episode(3, 6))   # 7 rows do not fit after 25: rows 0..6, episode 0 goes
    assert buffer.num_episodes == 3
    batch = buffer.transitions_at(buffer._transitions)
    assert set(batch["episode"].tolist()) == {1, 2, 3}
    check_histories(buffer, batch)
    buffer.extend(make_episode(4, 5))   # rows 7..12: overlaps episode 1's first rows only
    batch = buffer.transitions_at(buffer._transitions)
    assert set(batch["episode"].tolist()) == {2, 3, 4}
    assert buffer.num_transitions == 4 + 6 + 5
    check_histories(buffer, buffer.sample(300))
    with pytest.raises(ValueError, match="capacity"):
        buffer.extend(make_episode(5, 40))


def test_labels_follow_furl_rule():
    success = torch.tensor([False, False, True, True, False, True])
    assert episode_labels(success).tolist() == [1, 1, 1, 1, 0, 0]
    assert episode_labels(torch.zeros(3, dtype=torch.bool)).tolist() == [-1, -1, -1]
    assert episode_labels(torch.tensor([True])).tolist() == [1]

    buffer = EpisodeReplayBuffer(capacity=200, history=2)
    buffer.extend(make_episode(0, 10))
    assert not buffer.has_positives
    stage1 = buffer.sample_finetuning(8)
    assert set(stage1.keys()) == {"negative"}
    buffer.extend(make_episode(1, 30, successes=(14, 15, 16, 20)))
    assert buffer.has_positives
    positives = buffer.sample_states(400, POSITIVE)
    assert (positives["label"] == POSITIVE).all() and (positives["episode"] == 1).all()
    # states s_1 .. s_17: transitions 0..16 are positive (first success 14, then 15 and 16);
    # the reset frame s_0 is never labelled
    assert set(positives["step"].tolist()) == set(range(1, 18))
    negatives = buffer.sample_states(200, NEGATIVE)
    assert (negatives["episode"] == 0).all()
    assert torch.equal(marker(negatives["previous_embedding"]),
                       torch.clamp(negatives["step"] - 2, min=0).float())
    pairs = buffer.sample_positive_pairs(100, gap=10)
    assert torch.equal(pairs["later", "step"] - pairs["earlier", "step"], torch.full((100,), 10))
    assert torch.equal(pairs["later", "episode"], pairs["earlier", "episode"])
    assert (pairs["earlier", "label"] == POSITIVE).all()
    assert set(pairs["earlier", "step"].tolist()) == set(range(1, 8))
    assert buffer.sample_positive_pairs(4, gap=17) is None
    stage2 = buffer.sample_finetuning(8, gap=10)
    assert set(stage2.keys()) == {"negative", "positive", "positive_pair"}


def test_permanent_episodes_survive_wrap_around():
    """Preloaded experts are never overwritten: the ring wraps to the row after them."""
    buffer = EpisodeReplayBuffer(capacity=40, history=2)
    buffer.extend(make_episode(0, 9, successes=(8,)), permanent=True)  # rows 0..9
    for episode in range(1, 8):  # 10 rows each: the ring (rows 10..39) wraps twice
        buffer.extend(make_episode(episode, 9))
    assert buffer.num_permanent_episodes == 1 and buffer.has_positives
    stored = set(buffer.sample(2000)["episode"].tolist())
    assert stored == {0, 5, 6, 7}
    check_histories(buffer, buffer.sample(300))
    with pytest.raises(ValueError, match="before any other episode"):
        buffer.extend(make_episode(8, 9), permanent=True)
    with pytest.raises(ValueError, match="10 rows hold permanent episodes"):
        buffer.extend(make_episode(9, 30))


def test_label_window_keeps_most_recent():
    buffer = EpisodeReplayBuffer(capacity=500, history=2, label_window=12)
    for episode in range(4):
        buffer.extend(make_episode(episode, 9))
    negatives = buffer.sample_states(300, NEGATIVE)
    assert set(negatives["episode"].tolist()) <= {2, 3}


def test_goal_image_embedding_is_first_success_state():
    episode = make_episode(2, 10, successes=(6, 7))
    assert marker(goal_image_embedding(episode)).item() == 207.0


def test_memory_at_500k_transitions_is_under_budget():
    """Bytes per row measured on a full small buffer, extrapolated to 500,000 transitions of
    500-step episodes (501 rows each) with D = 1024."""
    capacity = 5 * 501
    buffer = EpisodeReplayBuffer(capacity=capacity, history=5)
    for episode in range(5):
        buffer.extend(make_episode(episode, 500, dim=1024))
    per_row = buffer.memory_bytes() / capacity
    rows = 1000 * 501
    assert per_row * rows < 1.2e9, per_row


def test_episodes_must_carry_the_same_keys():
    buffer = EpisodeReplayBuffer(capacity=50, history=2)
    buffer.extend(make_episode(0, 5).exclude("embedding", ("next", "embedding")))
    batch = buffer.sample(4)
    assert "embedding" not in batch["next"].keys() and batch["next", "observation"].shape == (4, 39)
    with pytest.raises(ValueError, match="same encoder, or none of them"):
        buffer.extend(make_episode(1, 5))
