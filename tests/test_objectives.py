"""Reward-finetuning losses against hand computations, and the stage switch."""

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.objectives import (
    CertaintyLoss,
    DirectionalLoss,
    PositionalRankingLoss,
    finetuning_losses,
)
from temporal_torchrl.rewards import DIRECTIONAL, TemporalReward

D = 2


def states(embeddings, previous=None, initial=None) -> TensorDict:
    embedding = torch.tensor(embeddings, dtype=torch.float32)
    return TensorDict({
        "embedding": embedding,
        "previous_embedding": embedding if previous is None else torch.tensor(previous),
        "initial_embedding": torch.zeros_like(embedding) if initial is None
        else torch.tensor(initial),
    }, [len(embeddings)])


def first_coordinate_loss(**kwargs) -> PositionalRankingLoss:
    """A loss whose reward is the first embedding coordinate, to check the arithmetic by hand."""
    reward = TemporalReward(D, torch.ones(D), -torch.ones(D), positional="furl",
                            directional=None)
    loss = PositionalRankingLoss(reward, torch.zeros(D), **kwargs)
    loss.positional_reward = lambda batch: batch["embedding"][:, 0]
    return loss


def test_neg_neg_ranking_by_hand():
    loss = first_coordinate_loss(stage=1)
    # rewards 0.1, 0.5, 0.0; distances to s_g = 0: 0.1, 0.5, 0.25
    negative = states([[0.1, 0.0], [0.5, 0.0], [0.0, 0.25]])
    out = loss(TensorDict({"negative": negative}, [3]))
    # pairs closer by more than 0.2: (1 over 2): relu(0.5 - 0.1 + 0.1) = 0.5;
    # (3 over 2): relu(0.5 - 0.0 + 0.1) = 0.6; (1 over 3) only 0.15 closer: ignored.
    assert out["loss_positional"].item() == pytest.approx((0.5 + 0.6) / 3)
    assert int(out["stage"]) == 1
    wide = first_coordinate_loss(stage=1, l2_margin=0.35)
    assert wide(TensorDict({"negative": negative}, [3]))["loss_positional"].item() == \
        pytest.approx(0.5 / 3)


def test_stage_two_pos_neg_and_pos_pos_by_hand():
    loss = first_coordinate_loss(stage=2, delta=0.1)
    batch = TensorDict({
        "negative": states([[0.3, 0.0], [0.0, 0.0]]),
        "positive": states([[0.35, 0.0], [1.0, 0.0]]),
        "positive_pair": TensorDict({"later": states([[0.2, 0.0], [0.9, 0.0]]),
                                     "earlier": states([[0.25, 0.0], [0.1, 0.0]])}, [2]),
    }, [2])
    out = loss(batch)
    # pos-neg: relu(0.3 - 0.35 + 0.1) = 0.05, relu(0 - 1 + 0.1) = 0 -> mean 0.025
    # pos-pos: relu(0.25 - 0.2 + 0.1) = 0.15, relu(0.1 - 0.9 + 0.1) = 0 -> mean 0.075
    assert out["loss_pos_neg"].item() == pytest.approx(0.025)
    assert out["loss_pos_pos"].item() == pytest.approx(0.075)
    assert out["loss_positional"].item() == pytest.approx(0.1)
    assert "loss_neg_neg" not in out.keys() and int(out["stage"]) == 2


def test_positional_loss_trains_only_positional_heads():
    torch.manual_seed(0)
    reward = TemporalReward(8, torch.randn(8), torch.randn(8), positional="p2", directional="d3")
    loss = PositionalRankingLoss(reward, torch.randn(8), stage=1)
    heads = {id(p) for p in reward.positional_heads.parameters()}
    assert {id(p) for p in loss.parameters()} == heads
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-2)
    negative = TensorDict({key: torch.randn(32, 8) for key in
                           ("embedding", "initial_embedding", "previous_embedding")}, [32])
    batch = TensorDict({"negative": negative}, [32])
    first = loss(batch)["loss_positional"]
    for _ in range(30):
        optimizer.zero_grad()
        loss(batch)["loss_positional"].backward()
        optimizer.step()
    assert loss(batch)["loss_positional"].item() < first.item()


@pytest.mark.parametrize("variant", ["d1", "d2", "d3", "d4", "d5"])
def test_directional_loss_matches_thesis_terms(variant):
    torch.manual_seed(1)
    dim = 6
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional=None,
                            directional=variant, lambda_=80.0)
    goal = torch.randn(dim)
    loss = DirectionalLoss(reward, goal, stage=1)
    negative = TensorDict({key: torch.randn(5, dim) for key in
                           ("embedding", "initial_embedding", "previous_embedding")}, [5])
    positive = TensorDict({key: torch.randn(5, dim) for key in
                           ("embedding", "initial_embedding", "previous_embedding")}, [5])
    fn = DIRECTIONAL[variant]
    common = {"g": reward.goal_embedding, "b": reward.baseline_embedding, "alpha": reward.alpha}
    heads = reward.directional_heads

    def r(s, s_prev, s0, position=None):
        return fn(heads, s, s0=s0, s_prev=s_prev, position=position, **common)

    n_t, n_tk, n_0 = negative["embedding"], negative["previous_embedding"], \
        negative["initial_embedding"]
    expected_negative = r(n_t, n_tk, n_0).mean() - r(goal.expand_as(n_t), n_t, n_0, n_t).mean()
    out = loss(TensorDict({"negative": negative}, [5]))
    assert out["loss_directional"].item() == pytest.approx(expected_negative.item(), abs=1e-6)
    assert int(out["stage"]) == 1

    p_t, p_tk, p_0 = positive["embedding"], positive["previous_embedding"], \
        positive["initial_embedding"]
    expected_positive = r(p_tk, p_t, p_0, p_t).mean() - r(p_t, p_tk, p_0).mean()
    loss.stage = 2
    out = loss(TensorDict({"negative": negative, "positive": positive}, [5]))
    assert out["loss_positive"].item() == pytest.approx(expected_positive.item(), abs=1e-6)
    assert out["loss_directional"].item() == pytest.approx(
        (expected_negative + expected_positive).item(), abs=1e-6)
    assert int(out["stage"]) == 2


def test_finetuning_batches_never_hold_the_reset_frame():
    """s_0 (step 0) is the same image in every episode of a fixed layout: it must be neither a
    positive nor a negative, and the directional loss never sees its zero direction."""
    from helpers import make_episode

    buffer = EpisodeReplayBuffer(capacity=300, k=2)
    buffer.extend(episode_rows(make_episode(0, 20)))
    buffer.extend(episode_rows(make_episode(1, 20, successes=(15,))))
    batch = buffer.finetuning.sample(500)
    for key in ("negative", "positive", ("positive_pair", "earlier")):
        assert (batch[key]["step"] >= 1).all(), key
    assert set(batch["negative", "step"].tolist()) == set(range(1, 21))
    # positives: FuRL's valid ones, s_11 .. s_16 (gap 10); their partners reach down to s_1
    assert set(batch["positive", "step"].tolist()) == set(range(11, 17))
    assert set(batch["positive_pair", "earlier", "step"].tolist()) == set(range(1, 7))


def test_joining_the_finetuning_groups_copies_nothing():
    """The layout converts all the groups' embeddings in one tensor, so the losses' joins of
    consecutive groups are views of it; any other join is torch.cat's, gradients included."""
    from helpers import make_episode

    from temporal_torchrl.objectives.finetuning.base import joined as _joined

    buffer = EpisodeReplayBuffer(capacity=300, k=2)
    buffer.extend(episode_rows(make_episode(0, 20)))
    buffer.extend(episode_rows(make_episode(1, 20, successes=(15,))))
    batch = buffer.finetuning.sample(8)
    groups = [batch["negative"], batch["positive"], batch["positive_pair", "later"],
              batch["positive_pair", "earlier"]]
    for key in ("embedding", "initial_embedding", "previous_embedding"):
        parts = [states[key] for states in groups]
        joined = _joined(parts)
        torch.testing.assert_close(joined, torch.cat(parts), rtol=0, atol=0)
        assert joined.data_ptr() == parts[0].data_ptr()  # a view: nothing copied
    reordered = [batch["positive", "embedding"], batch["negative", "embedding"]]
    joined = _joined(reordered)
    torch.testing.assert_close(joined, torch.cat(reordered), rtol=0, atol=0)
    assert joined.data_ptr() != reordered[0].data_ptr()
    trained = batch["negative", "embedding"].clone().requires_grad_()
    _joined([trained, batch["positive", "embedding"]]).sum().backward()
    torch.testing.assert_close(trained.grad, torch.ones_like(trained))


def test_directional_release_option_scores_contrast_at_plain_position():
    torch.manual_seed(2)
    dim = 6
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional=None,
                            directional="d4")
    goal = torch.randn(dim)
    thesis = DirectionalLoss(reward, goal, stage=1)
    release = DirectionalLoss(reward, goal, stage=1, same_position=False)
    negative = TensorDict({key: torch.randn(5, dim) for key in
                           ("embedding", "initial_embedding", "previous_embedding")}, [5])
    s_t = negative["embedding"]
    common = {"g": reward.goal_embedding, "b": reward.baseline_embedding, "alpha": reward.alpha,
              "s0": negative["initial_embedding"]}
    heads = reward.directional_heads
    observed = DIRECTIONAL["d4"](heads, s_t, s_prev=negative["previous_embedding"], **common,
                                 projection="origin")
    towards_plain = DIRECTIONAL["d3"](heads, goal.expand_as(s_t), s_prev=s_t, position=s_t,
                                      **common)
    batch = TensorDict({"negative": negative}, [5])
    assert release(batch)["loss_directional"].item() == pytest.approx(
        (observed.mean() - towards_plain.mean()).item(), abs=1e-6)
    assert thesis(batch)["loss_directional"].item() != pytest.approx(
        release(batch)["loss_directional"].item(), abs=1e-6)


def test_stage_switch_follows_the_first_positive_episode():
    from helpers import make_episode

    buffer = EpisodeReplayBuffer(capacity=300, k=2)
    reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional="furl",
                            directional="d3")
    positional = PositionalRankingLoss(reward, torch.randn(4), stage=1)
    directional = DirectionalLoss(reward, torch.randn(4), stage=1)
    buffer.extend(episode_rows(make_episode(0, 20)))
    batch = buffer.finetuning.sample(16)
    assert int(positional(batch)["stage"]) == 1 and int(directional(batch)["stage"]) == 1
    buffer.extend(episode_rows(make_episode(1, 20, successes=(15,))))
    positional.stage = directional.stage = buffer.stage
    batch = buffer.finetuning.sample(16)
    out = positional(batch)
    assert int(out["stage"]) == 2 and {"loss_pos_neg", "loss_pos_pos"} <= set(out.keys())
    assert int(directional(batch)["stage"]) == 2


def test_losses_need_heads():
    reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional="liv",
                            directional=None)
    with pytest.raises(ValueError, match="positional"):
        PositionalRankingLoss(reward, torch.zeros(4), stage=1)
    with pytest.raises(ValueError, match="directional"):
        DirectionalLoss(reward, torch.zeros(4), stage=1)


# --- beyond the thesis: d_sequence (6.3) and d_certainty (6.4) ----------------------------------

def window_states(generator, count, dim, window_length):
    window = torch.randn(count, window_length, dim, generator=generator)
    return TensorDict({"embedding": window[:, -1], "previous_embedding": window[:, -3],
                       "initial_embedding": window[:, 0], "embedding_window": window}, [count])


def test_directional_loss_of_a_window_reward_by_hand():
    """d_sequence: observed windows against the straight window to s_g (stage 1) and the
    reversed window (stage 2), all at the position s_t, written out."""
    gen = torch.Generator().manual_seed(5)
    dim, length = 6, 4
    reward = TemporalReward(dim, torch.randn(dim, generator=gen), torch.randn(dim, generator=gen),
                            positional=None, directional="d_sequence", options={"window": length})
    goal = torch.randn(dim, generator=gen)
    loss = DirectionalLoss(reward, goal, stage=2)
    negative, positive = (window_states(gen, 5, dim, length) for _ in range(2))
    common = {"g": reward.goal_embedding, "b": reward.baseline_embedding}
    heads = reward.directional_heads

    def r(window, position):
        return DIRECTIONAL["d_sequence"](heads, window[:, -1], window=window, position=position,
                                         **common)

    n_window, n_t = negative["embedding_window"], negative["embedding"]
    straight = torch.stack([n_t + j / (length - 1) * (goal - n_t) for j in range(length)], 1)
    expected_negative = r(n_window, n_t).mean() - r(straight, n_t).mean()
    p_window, p_t = positive["embedding_window"], positive["embedding"]
    reversed_window = p_window[:, [3, 2, 1, 0]]
    expected_positive = r(reversed_window, p_t).mean() - r(p_window, p_t).mean()
    out = loss(TensorDict({"negative": negative, "positive": positive}, [5]))
    assert out["loss_negative"].item() == pytest.approx(expected_negative.item(), abs=1e-6)
    assert out["loss_positive"].item() == pytest.approx(expected_positive.item(), abs=1e-6)
    assert out["loss_directional"].requires_grad
    with pytest.raises(KeyError, match="window_length=4"):
        loss(TensorDict({"negative": negative.exclude("embedding_window")}, [5]))


def certainty_batch():
    """Positives at e1 that moved along e2 (s_(t-k) = e1 - e2), negatives at e1 that moved along
    e3; the goal image s_g = e1 + e2 lies along the positives' move."""
    e1, e2, e3 = torch.eye(3)

    def states(previous):
        return TensorDict({"embedding": torch.stack([e1, e1]),
                           "previous_embedding": torch.stack([previous, previous]),
                           "initial_embedding": torch.zeros(2, 3)}, [2])

    return states(e1 - e3), states(e1 - e2), e1 + e2


def test_certainty_loss_by_hand():
    """Targets by hand (beta 0.1, c 1; position scale EPS, direction scale 1, see
    test_rewards.test_reference_scales_by_hand), each observed direction leaving itself out:
    observed positive (1 - 2 q)/(2 + 2 q) with q = exp(-10), observed negative the opposite,
    towards the goal (along e2, both positives count) (2 - 2 q)/(3 + 2 q), the positives'
    opposite direction -e2 (2 exp(-20) - 2 q)/(1 + 2 exp(-20) + 2 q), about 0."""
    negative, positive, goal = certainty_batch()
    torch.manual_seed(6)
    reward = TemporalReward(3, torch.randn(3), torch.randn(3), positional=None,
                            directional="d_certainty")
    loss = CertaintyLoss(reward, goal, stage=1)
    q, far = np.exp(-10.0), np.exp(-20.0)
    t_positive, t_goal = (1 - 2 * q) / (2 + 2 * q), (2 - 2 * q) / (3 + 2 * q)
    t_opposite = (2 * far - 2 * q) / (1 + 2 * far + 2 * q)
    s_t = positive["embedding"]

    def r(s, s_prev):
        return reward.directional_reward(s, s_prev, position=s_t).detach()

    expected_negative = ((r(s_t, negative["previous_embedding"]) + t_positive) ** 2).mean() + \
        ((r(goal.expand_as(s_t), s_t) - t_goal) ** 2).mean()
    expected_positive = ((r(s_t, positive["previous_embedding"]) - t_positive) ** 2).mean() + \
        ((r(positive["previous_embedding"], s_t) - t_opposite) ** 2).mean()
    stage1 = loss(TensorDict({"negative": negative}, [2]))
    # Stage 1 has negatives only: the observed ones get (-1 + ...)/(1 + 1) from their twin.
    assert stage1["target_negative"].item() == pytest.approx(-1 / 2, abs=1e-6)
    loss.stage = 2
    out = loss(TensorDict({"negative": negative, "positive": positive}, [2]))
    assert out["target_positive"].item() == pytest.approx(t_positive, abs=1e-6)
    assert out["target_negative"].item() == pytest.approx(-t_positive, abs=1e-6)
    assert out["loss_certainty_negative"].item() == pytest.approx(expected_negative.item(),
                                                                  abs=1e-6)
    assert out["loss_certainty_positive"].item() == pytest.approx(expected_positive.item(),
                                                                  abs=1e-6)
    assert out["loss_certainty"].item() == pytest.approx(
        (expected_negative + expected_positive).item(), abs=1e-6)
    assert int(out["stage"]) == 2 and int(stage1["stage"]) == 1


@pytest.mark.slow
def test_certainty_loss_trains_graded_rewards():
    """The heads learn the targets: -0.5 for the negatives' move, about 0 for the opposite of
    the positives' move, and for the positives' move, which is also the move towards the goal
    (one input, targets 1/2 observed and 2/3 towards the goal), their mean 7/12: graded values,
    not D3's saturated +-1."""
    negative, positive, goal = certainty_batch()
    torch.manual_seed(7)
    reward = TemporalReward(3, torch.randn(3), torch.randn(3), positional=None,
                            directional="d_certainty")
    loss = CertaintyLoss(reward, goal, stage=2)
    optimizer = torch.optim.Adam(loss.parameters(), lr=3e-3)
    batch = TensorDict({"negative": negative, "positive": positive}, [2])
    for _ in range(300):
        optimizer.zero_grad()
        loss(batch)["loss_certainty"].backward()
        optimizer.step()
    s_t = positive["embedding"][:1]
    rewards = [reward.directional_reward(end, start, position=s_t).item() for end, start in (
        (s_t, positive["previous_embedding"][:1]), (s_t, negative["previous_embedding"][:1]),
        (goal.unsqueeze(0), s_t), (positive["previous_embedding"][:1], s_t))]
    np.testing.assert_allclose(rewards, [7 / 12, -0.5, 7 / 12, 0.0], atol=0.02)


def test_finetuning_losses_follow_the_registered_objective():
    torch.manual_seed(8)
    pairs = {("furl", "d3"): [PositionalRankingLoss, DirectionalLoss],
             ("p2", "d_certainty"): [PositionalRankingLoss, CertaintyLoss],
             (None, "d_sequence"): [DirectionalLoss], ("liv", None): []}
    for (positional, directional), expected in pairs.items():
        reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional=positional,
                                directional=directional)
        losses = finetuning_losses(reward, torch.randn(4), stage=1, delta=0.2,
                                   same_position=False)
        assert [type(loss) for loss in losses] == expected
    assert losses == [] and finetuning_losses(
        TemporalReward(4, torch.randn(4), torch.randn(4)), torch.randn(4), stage=1)[0].delta == 0.1
    windowed = TemporalReward(4, torch.randn(4), torch.randn(4), directional="d_sequence")
    with pytest.raises(ValueError, match="reads a window"):
        CertaintyLoss(windowed, torch.randn(4), stage=1)


def test_directional_losses_refresh_the_certainty_references():
    """certainty_scaling: each update's labelled states (s_t, s_t - s_(t-k), +-1) become the
    references the reward scores with."""
    negative, positive, goal = certainty_batch()
    reward = TemporalReward(3, torch.randn(3), torch.randn(3), positional=None, directional="d3",
                            certainty_scaling=True)
    DirectionalLoss(reward, goal, stage=2)(TensorDict({"negative": negative, "positive": positive},
                                                      [2]))
    memory = reward.certainty
    assert memory.labels.tolist() == [-1.0, -1.0, 1.0, 1.0]
    torch.testing.assert_close(memory.directions, torch.eye(3)[[2, 2, 1, 1]])
    torch.testing.assert_close(memory.scales, torch.tensor([1e-8, 1.0]))


@pytest.mark.parametrize("directional", ["d3", "d_certainty", "d_sequence"])
@pytest.mark.parametrize("stage", [1, 2])
def test_each_loss_sums_its_terms_exactly(directional, stage):
    """``terms`` is the loss before the sum: ``forward`` returns each ``loss_*`` term (detached)
    and the metrics as ``terms`` gives them, and ``loss_key`` is exactly their sum, bit for bit,
    for every built-in loss in both stages (a stage-2 batch from a replay buffer)."""
    from helpers import synthetic_episode

    torch.manual_seed(9)
    reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional="furl",
                            directional=directional, k=2)
    buffer = EpisodeReplayBuffer(capacity=300, reward=reward, gap=3,
                                 window_length=reward.window_length)
    for number in range(3):
        success = torch.arange(20) >= 15 if number == 1 else None
        buffer.extend(episode_rows(synthetic_episode(torch.randn(21, 4), success),
                                   embedding_dtype=torch.float32))
    batch = buffer.finetuning.sample(16)
    for loss in finetuning_losses(reward, torch.randn(4), stage=stage):
        terms = loss.terms(batch)
        out = loss(batch)
        parts = [name for name in terms if name.startswith("loss_")]
        assert parts and int(out["summed_parts"]) == len(parts)
        for name, value in terms.items():
            assert torch.equal(out[name], value.detach()), name
        assert torch.equal(out[loss.loss_key],
                           torch.stack([terms[name] for name in parts]).sum())
        assert out[loss.loss_key].requires_grad


def test_a_term_named_like_the_sum_is_refused():
    class Clashing(DirectionalLoss):
        def terms(self, tensordict):
            return {**super().terms(tensordict), self.loss_key: torch.zeros(())}

    reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional=None)
    with pytest.raises(ValueError, match=r"Clashing\.terms\(\) returned an entry named "
                                         r"'loss_directional', the key of the loss's sum"):
        Clashing(reward, torch.zeros(D), stage=1)(TensorDict({"negative": states([[1.0, 0.0]])},
                                                             [1]))
