"""Episode replay on TorchRL's buffer API: histories by index, boundaries, starts, overwrite,
labels, finetuning groups, the relabelling transform, TorchRL's dumps/loads, memory."""

import pytest
import torch
from helpers import D, insert, make_episode, marker
from tensordict import TensorDict

from temporal_torchrl.data import (
    POSITIVE,
    EpisodeReplayBuffer,
    episode_labels,
    episode_rows,
    goal_image_embedding,
    transition_index,
)
from temporal_torchrl.encoders import load_encoder


def all_transitions(buffer: EpisodeReplayBuffer) -> TensorDict:
    """Every sampleable transition, through the buffer's own index arithmetic and transform."""
    rows = buffer.writer.rows()
    return buffer[transition_index(rows["transitions"], rows["steps"], buffer.k,
                                   buffer.window_length)]


def check_histories(buffer: EpisodeReplayBuffer, batch: TensorDict) -> None:
    k = buffer.k
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
    buffer = EpisodeReplayBuffer(capacity=200, k=3)
    for episode, steps in enumerate((7, 2, 12)):
        insert(buffer, episode, steps)
    assert buffer.num_transitions == 7 + 2 + 12
    batch = all_transitions(buffer)
    check_histories(buffer, batch)
    # every step of every episode, starts included, is a sampleable transition
    pairs = set(zip(batch["episode"].tolist(), batch["step"].tolist(), strict=True))
    assert pairs == {(e, t) for e, n in enumerate((7, 2, 12)) for t in range(n)}
    last = batch["next", "truncated"].squeeze(-1)
    assert torch.equal(last, batch["step"] == torch.tensor([7, 2, 12])[batch["episode"]] - 1)
    assert not batch["next", "terminated"].any()
    assert torch.equal(batch["next", "reward"], batch["next", "success"].float() - 1.0)
    sampled = buffer.sample(500)
    check_histories(buffer, sampled)
    assert (sampled["step"] == 0).any()
    assert sampled["next", "embedding"].dtype == torch.float32
    assert buffer.storage.get(slice(None))["embedding"].dtype == torch.float16


def test_windows_by_index_are_padded_at_starts_and_never_cross_episodes():
    """The window s_(t-K+1) .. s_t of every state (finetuning) and s_(t+2-K) .. s_(t+1) of every
    transition (relabelling), with a ring that wrapped: episode 2 went to rows 0..9 (episode 0
    overwritten), episode 1 sits at rows 12..22 after stale rows of episode 0, so a window
    reaching past a start would read another episode's marker (or the storage's last row)."""
    length = 4
    buffer = EpisodeReplayBuffer(capacity=24, k=2, window_length=length)
    for episode, steps in enumerate((11, 10, 9)):  # the third wraps to row 0
        insert(buffer, episode, steps)
    assert buffer.num_episodes == 2
    batch = all_transitions(buffer)
    check_histories(buffer, batch)
    expected = (100.0 * batch["episode"].unsqueeze(-1) + torch.clamp(
        batch["step"].unsqueeze(-1) + 1 - torch.arange(length - 1, -1, -1), min=0))
    assert torch.equal(marker(batch["next", "embedding_window"]), expected)
    negatives = buffer.finetuning.sample(500)["negative"]
    window = marker(negatives["embedding_window"])
    step = negatives["step"].unsqueeze(-1)
    assert torch.equal(window, 100.0 * negatives["episode"].unsqueeze(-1) + torch.clamp(
        step - torch.arange(length - 1, -1, -1), min=0))
    assert torch.equal(window[:, -1], marker(negatives["embedding"]))
    assert {tuple(row) for row in window[negatives["episode"] == 2].tolist()} >= {
        (200.0, 200.0, 200.0, 201.0), (200.0, 200.0, 201.0, 202.0),
        (200.0, 201.0, 202.0, 203.0)}
    assert torch.equal(negatives["embedding_window"][:, -1], negatives["embedding"])
    # Stage 2: the labelled states carry their windows; the pair's states, which only the
    # positional ranking loss reads, carry none (their windows are never converted).
    staged = EpisodeReplayBuffer(capacity=60, k=2, window_length=length, gap=3)
    insert(staged, 0, 10)
    insert(staged, 1, 20, successes=(12, 13))
    batch = staged.finetuning.sample(64)
    for name in ("negative", "positive"):
        states = batch[name]
        assert torch.equal(marker(states["embedding_window"]), 100.0 * states["episode"].unsqueeze(
            -1) + torch.clamp(states["step"].unsqueeze(-1) - torch.arange(length - 1, -1, -1),
                              min=0))
    for state in ("later", "earlier"):
        assert "embedding_window" not in batch["positive_pair", state].keys()
        assert "embedding" in batch["positive_pair", state].keys()
    plain = EpisodeReplayBuffer(capacity=24, k=2)
    insert(plain, 0, 5)
    assert "embedding_window" not in plain.sample(4)["next"].keys()
    with pytest.raises(ValueError, match="window_length=1"):
        EpisodeReplayBuffer(capacity=24, window_length=1)


def test_overwrite_invalidates_whole_old_episodes():
    buffer = EpisodeReplayBuffer(capacity=30, k=2)
    insert(buffer, 0, 9)   # rows 0..9
    insert(buffer, 1, 9)   # rows 10..19
    insert(buffer, 2, 4)   # rows 20..24
    assert insert(buffer, 3, 6).tolist() == list(range(7))  # no room after 25: episode 0 goes
    assert buffer.num_episodes == 3
    batch = all_transitions(buffer)
    assert set(batch["episode"].tolist()) == {1, 2, 3}
    check_histories(buffer, batch)
    insert(buffer, 4, 5)   # rows 7..12: overlaps episode 1's first rows only
    batch = all_transitions(buffer)
    assert set(batch["episode"].tolist()) == {2, 3, 4}
    assert buffer.num_transitions == 4 + 6 + 5
    check_histories(buffer, buffer.sample(300))
    with pytest.raises(ValueError, match="capacity"):
        insert(buffer, 5, 40)
    with pytest.raises(RuntimeError, match="whole episodes"):
        buffer.add(episode_rows(make_episode(6, 3))[0])


def test_labels_follow_furl_rule_and_groups_follow_the_stage():
    success = torch.tensor([False, False, True, True, False, True])
    assert episode_labels(success).tolist() == [1, 1, 1, 1, 0, 0]
    assert episode_labels(torch.zeros(3, dtype=torch.bool)).tolist() == [-1, -1, -1]
    assert episode_labels(torch.tensor([True])).tolist() == [1]

    buffer = EpisodeReplayBuffer(capacity=200, k=2, gap=10)
    insert(buffer, 0, 10)
    assert buffer.stage == 1
    assert set(buffer.finetuning.sample(8).keys()) == {"negative"}
    insert(buffer, 1, 30, successes=(14, 15, 16, 20))
    assert buffer.stage == 2
    batch = buffer.finetuning.sample(400)
    assert set(batch.keys()) == {"negative", "positive", "positive_pair"}
    positives = batch["positive"]
    assert (positives["label"] == POSITIVE).all() and (positives["episode"] == 1).all()
    # states s_1 .. s_17 are labelled positive (transitions 0..16: first success 14, then 15
    # and 16; the reset frame s_0 never is); FuRL draws only the valid ones, s_11 .. s_17
    assert set(positives["step"].tolist()) == set(range(11, 18))
    assert buffer.num_positive_states == 17
    negatives = batch["negative"]
    assert (negatives["episode"] == 0).all()
    assert set(negatives["step"].tolist()) == set(range(1, 11))
    assert torch.equal(marker(negatives["embedding"]), negatives["step"].float())
    assert torch.equal(marker(negatives["previous_embedding"]),
                       torch.clamp(negatives["step"] - 2, min=0).float())
    assert (marker(negatives["initial_embedding"]) == 0).all()
    pairs = batch["positive_pair"]
    assert torch.equal(pairs["later", "step"] - pairs["earlier", "step"], torch.full((400,), 10))
    assert torch.equal(pairs["later", "episode"], pairs["earlier", "episode"])
    assert torch.equal(marker(pairs["later", "embedding"]) - marker(pairs["earlier", "embedding"]),
                       torch.full((400,), 10.0))
    assert (pairs["earlier", "label"] == POSITIVE).all()
    assert set(pairs["earlier", "step"].tolist()) == set(range(1, 8))
    no_pairs = EpisodeReplayBuffer(capacity=200, k=2, gap=17)
    insert(no_pairs, 1, 30, successes=(14, 15, 16, 20))
    assert set(no_pairs.finetuning.sample(4).keys()) == {"positive"}
    # with no valid positive yet, the positives fall back to every positive state
    assert set(no_pairs.finetuning.sample(400)["positive", "step"].tolist()) == set(range(1, 18))


def test_pos_neg_positives_never_below_gap_over_many_draws():
    """FuRL's rule written out: a positive drawn for the pos-neg term has a lagged partner in
    its positive run, i.e. its step is above gap, on a 28-step positive episode."""
    gap = 10
    buffer = EpisodeReplayBuffer(capacity=400, k=5, gap=gap)
    insert(buffer, 0, 40)
    insert(buffer, 1, 28, successes=(27,))  # states s_1 .. s_28 positive
    steps = torch.cat([buffer.finetuning.sample(256)["positive", "step"] for _ in range(40)])
    assert int(steps.min()) == gap + 1 and int(steps.max()) == 28
    # and each valid state is drawn: s_11 .. s_28, 18 states, uniformly
    counts = torch.bincount(steps, minlength=29)[gap + 1:]
    assert counts.numel() == 18 and int(counts.min()) > 0.6 * steps.numel() / 18


def test_stage1_negatives_reach_the_oldest_episodes():
    """Before any positive, FuRL's neg-neg batch comes from the whole buffer: label_window
    (FuRL's stage-2 FIFO) does not apply; after a positive episode it does."""
    buffer = EpisodeReplayBuffer(capacity=1000, k=2, label_window=20)
    for episode in range(10):
        insert(buffer, episode, 9)  # 90 negative states, 4.5 windows
    drawn = torch.cat([buffer.finetuning.sample(512)["negative", "episode"] for _ in range(8)])
    assert set(drawn.tolist()) == set(range(10))
    insert(buffer, 10, 12, successes=(11,))
    drawn = buffer.finetuning.sample(2000)["negative", "episode"]
    assert set(drawn.tolist()) == {7, 8, 9}  # the 20 most recent negatives: 2 + 9 + 9


def test_permanent_episodes_survive_wrap_around():
    """Preloaded experts are never overwritten: the ring wraps to the row after them."""
    buffer = EpisodeReplayBuffer(capacity=40, k=2, permanent_episodes=1)
    insert(buffer, 0, 9, successes=(8,))  # rows 0..9
    for episode in range(1, 8):  # 10 rows each: the ring (rows 10..39) wraps twice
        insert(buffer, episode, 9)
    assert buffer.num_permanent_episodes == 1 and buffer.stage == 2
    stored = set(buffer.sample(2000)["episode"].tolist())
    assert stored == {0, 5, 6, 7}
    check_histories(buffer, buffer.sample(300))
    with pytest.raises(ValueError, match="10 rows hold permanent episodes"):
        insert(buffer, 9, 30)
    too_big = EpisodeReplayBuffer(capacity=40, k=2, permanent_episodes=2)
    insert(too_big, 0, 25, successes=(8,))
    with pytest.raises(ValueError, match="permanent episodes fill more than"):
        insert(too_big, 1, 20, successes=(8,))


def test_label_window_keeps_most_recent():
    buffer = EpisodeReplayBuffer(capacity=500, k=2, label_window=12)
    for episode in range(4):
        insert(buffer, episode, 9)
    insert(buffer, 4, 3, successes=(1,))  # a positive: stage 2, where FuRL has the window
    negatives = buffer.finetuning.sample(300)["negative"]
    assert set(negatives["episode"].tolist()) == {2, 3}
    assert set(zip(negatives["episode"].tolist(), negatives["step"].tolist(), strict=True)) == {
        (2, t) for t in range(7, 10)} | {(3, t) for t in range(1, 10)}


def test_sac_batches_are_relabelled_by_the_reward_as_it_is_now():
    """The buffer's transform is the env's reward transform: changing the heads changes the
    sampled rewards, and each equals the reward recomputed from the batch's embeddings."""
    from temporal_torchrl.rewards import TemporalReward

    reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="furl",
                            directional="d3", rho=1.0, lambda_=2.0, k=2)
    buffer = EpisodeReplayBuffer(capacity=100, k=2, reward=reward, batch_size=64)
    insert(buffer, 0, 30, successes=(20,))
    for _ in range(2):
        batch = buffer.sample()
        nxt = batch["next"]
        with torch.no_grad():
            expected = reward(nxt["embedding"], nxt["initial_embedding"],
                              nxt["previous_embedding"], nxt["success"])["reward"]
        torch.testing.assert_close(nxt["reward"], expected)
        assert not torch.equal(nxt["reward"], nxt["success"].float() - 1.0)
        with torch.no_grad():
            for parameter in reward.parameters():
                parameter.add_(1.0)


def test_history_comes_from_the_reward_and_a_different_one_is_refused():
    """k has one route: with a reward the buffer takes the reward's k (the env's history
    transform's), and a different explicit ``k`` is refused, naming both values; so is a
    reward-head trainer on a buffer of another k, and an env built with another k."""
    from temporal_torchrl.envs import make_temporal_env
    from temporal_torchrl.rewards import TemporalReward
    from temporal_torchrl.training import RewardHeadTrainer

    reward = TemporalReward(D, torch.randn(D), torch.randn(D), k=5)
    assert EpisodeReplayBuffer(capacity=100, reward=reward).k == 5
    assert EpisodeReplayBuffer(capacity=100, k=5, reward=reward).k == 5
    assert EpisodeReplayBuffer(capacity=100).k == 5  # no reward: the default
    message = (r"EpisodeReplayBuffer: k=3 but reward\.k=5: s_\(t-3\) here against the "
               r"s_\(t-5\) of the reward's history transform\. Leave k out \(it is taken from "
               r"the reward\) or build the reward with k=3\.")
    with pytest.raises(ValueError, match=message):
        EpisodeReplayBuffer(capacity=1000, k=3, reward=reward)
    other = EpisodeReplayBuffer(capacity=100, k=3)
    insert(other, 0, 10)
    with pytest.raises(ValueError, match=r"RewardHeadTrainer: the replay's k=3 but "
                                         r"reward\.k=5.*EpisodeReplayBuffer\(\.\.\., "
                                         r"reward=reward\)"):
        RewardHeadTrainer(reward, torch.randn(D), other.finetuning)
    with pytest.raises(ValueError, match=r"make_temporal_env: k=3 but reward\.k=5"):
        make_temporal_env("drawer-open", encoder=load_encoder("state", dim=D), reward=reward,
                          k=3)


def test_the_deprecated_history_keyword_warns_and_a_different_k_is_refused():
    """``history=``, k's name before, is read for one more release with a FutureWarning that
    names ``k=`` (the buffer, the env, the offline finetuning buffer); given beside a different
    ``k`` it is refused, naming both."""
    from temporal_torchrl.envs import make_temporal_env
    from temporal_torchrl.reward_quality import make_finetuning_buffer

    with pytest.warns(FutureWarning, match=r"EpisodeReplayBuffer: history= is deprecated.*k="):
        assert EpisodeReplayBuffer(capacity=100, history=3).k == 3
    with pytest.warns(FutureWarning, match=r"EpisodeReplayBuffer: history= is deprecated"):
        assert EpisodeReplayBuffer(capacity=100, k=3, history=3).k == 3
    with pytest.raises(ValueError, match=r"EpisodeReplayBuffer: k=2 and history=3 differ"):
        EpisodeReplayBuffer(capacity=100, k=2, history=3)
    with pytest.warns(FutureWarning, match=r"EpisodeReplayBuffer.history is deprecated.*\.k"):
        assert EpisodeReplayBuffer(capacity=100, k=4).history == 4
    with pytest.warns(FutureWarning, match=r"make_finetuning_buffer: history= is deprecated"):
        assert make_finetuning_buffer([make_episode(0, 5)], history=3).k == 3
    with pytest.raises(ValueError, match=r"make_temporal_env: k=2 and history=3 differ"):
        make_temporal_env("drawer-open", encoder=load_encoder("state", dim=D), k=2, history=3)


def test_no_history_keyword_is_left_in_the_package_but_the_deprecated_shims():
    """k has one name: the package's source takes no ``history`` argument and passes no
    ``history=`` keyword, but for the public signatures that read the deprecated keyword and
    the shim that does (:func:`~temporal_torchrl.rewards.temporal.renamed_k`)."""
    import ast
    from pathlib import Path

    import temporal_torchrl

    shims = {"EpisodeReplayBuffer.__init__", "make_temporal_env", "make_finetuning_buffer",
             "renamed_k", "EpisodeReplayBuffer.history"}
    found = set()
    package = Path(temporal_torchrl.__file__).parent
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                assert "history" not in {keyword.arg for keyword in node.keywords}, \
                    f"{path}:{node.lineno} passes history="
            if isinstance(node, ast.ClassDef):
                for method in node.body:
                    if isinstance(method, ast.FunctionDef):
                        method.qualname = f"{node.name}.{method.name}"
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                name = getattr(node, "qualname", node.name)
                arguments = node.args.args + node.args.kwonlyargs
                if name.endswith(".history") or "history" in {a.arg for a in arguments}:
                    found.add(name)
    assert found == shims


def test_buffer_state_round_trips_through_torchrl_dumps_and_loads(tmp_path):
    """TorchRL's own checkpointing (storage, writer, sampler) restores the episodes, the ring's
    cursor and the permanent rows: the next write lands where it would have."""
    buffer = EpisodeReplayBuffer(capacity=40, k=2, permanent_episodes=1)
    insert(buffer, 0, 9, successes=(8,))
    for episode in range(1, 5):
        insert(buffer, episode, 9)
    buffer.dumps(tmp_path / "buffer")
    restored = EpisodeReplayBuffer(capacity=40, k=2, permanent_episodes=1)
    restored.loads(tmp_path / "buffer")
    assert restored.writer.episodes == buffer.writer.episodes
    assert torch.equal(all_transitions(restored)["next", "embedding"],
                       all_transitions(buffer)["next", "embedding"])
    # episodes 1..3 filled rows 10..39, episode 4 wrapped to rows 10..19 (after the expert)
    assert insert(restored, 5, 9).tolist() == insert(buffer, 5, 9).tolist() == list(range(20, 30))


def test_goal_image_embedding_is_first_success_state():
    episode = make_episode(2, 10, successes=(6, 7))
    assert marker(goal_image_embedding(episode)).item() == 207.0


def test_memory_at_500k_transitions_is_under_budget():
    """Bytes per row measured on a full small buffer, extrapolated to 500,000 transitions of
    500-step episodes (501 rows each) with D = 1024."""
    capacity = 5 * 501
    buffer = EpisodeReplayBuffer(capacity=capacity, k=5)
    for episode in range(5):
        insert(buffer, episode, 500, dim=1024)
    per_row = buffer.memory_bytes() / capacity
    rows = 1000 * 501
    assert per_row * rows < 1.2e9, per_row


def test_episodes_must_carry_the_same_keys():
    buffer = EpisodeReplayBuffer(capacity=50, k=2)
    buffer.extend(episode_rows(make_episode(0, 5).exclude("embedding", ("next", "embedding"))))
    batch = buffer.sample(4)
    assert "embedding" not in batch["next"].keys() and batch["next", "observation"].shape == (4, 39)
    with pytest.raises(ValueError, match="same encoder, or none of them"):
        insert(buffer, 1, 5)


def test_whole_preloaded_positive_gives_sac_its_reward_zero_transitions():
    """A preloaded episode kept whole puts every transition in SAC's buffer with its task reward:
    counted here from the success pattern the episode was built with (success after steps
    100..299, lost, back after 400..499), not from the buffer's labels."""
    successes = list(range(100, 300)) + list(range(400, 500))
    buffer = EpisodeReplayBuffer(capacity=600, k=5, permanent_episodes=1)
    insert(buffer, 0, 500, successes=successes)
    transitions = all_transitions(buffer)
    assert buffer.num_transitions == transitions.shape[0] == 500
    assert int((transitions["next", "reward"] == 0).sum()) == len(successes) == 300
    # The finetuning's positives run from the start to where success is first lost: s_1..s_300
    assert buffer.num_positive_states == 300
    cut = EpisodeReplayBuffer(capacity=600, k=5, permanent_episodes=1)
    insert(cut, 0, 106, successes=range(100, 106))  # the old preload: cut 5 steps after
    assert int((all_transitions(cut)["next", "reward"] == 0).sum()) == 6
