"""Reward-finetuning losses against hand computations, and the stage switch."""

import pytest
import torch
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer
from temporal_torchrl.objectives import DirectionalLoss, PositionalRankingLoss
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
    reward = TemporalReward(D, torch.ones(D), -torch.ones(D), positional="furl")
    loss = PositionalRankingLoss(reward, torch.zeros(D), **kwargs)
    loss.positional_reward = lambda batch: batch["embedding"][:, 0]
    return loss


def test_neg_neg_ranking_by_hand():
    loss = first_coordinate_loss()
    # rewards 0.1, 0.5, 0.0; distances to s_g = 0: 0.1, 0.5, 0.25
    negative = states([[0.1, 0.0], [0.5, 0.0], [0.0, 0.25]])
    out = loss(TensorDict({"negative": negative}, [3]))
    # pairs closer by more than 0.2: (1 over 2): relu(0.5 - 0.1 + 0.1) = 0.5;
    # (3 over 2): relu(0.5 - 0.0 + 0.1) = 0.6; (1 over 3) only 0.15 closer: ignored.
    assert out["loss_positional"].item() == pytest.approx((0.5 + 0.6) / 3)
    assert int(out["stage"]) == 1
    wide = first_coordinate_loss(l2_margin=0.35)
    assert wide(TensorDict({"negative": negative}, [3]))["loss_positional"].item() == \
        pytest.approx(0.5 / 3)


def test_stage_two_pos_neg_and_pos_pos_by_hand():
    loss = first_coordinate_loss(delta=0.1)
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
    loss = PositionalRankingLoss(reward, torch.randn(8))
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
    loss = DirectionalLoss(reward, goal)
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
    out = loss(TensorDict({"negative": negative, "positive": positive}, [5]))
    assert out["loss_positive"].item() == pytest.approx(expected_positive.item(), abs=1e-6)
    assert out["loss_directional"].item() == pytest.approx(
        (expected_negative + expected_positive).item(), abs=1e-6)
    assert int(out["stage"]) == 2


def test_finetuning_batches_never_hold_the_reset_frame():
    """s_0 (step 0) is the same image in every episode of a fixed layout: it must be neither a
    positive nor a negative, and the directional loss never sees its zero direction."""
    from test_replay import make_episode

    buffer = EpisodeReplayBuffer(capacity=300, history=2)
    buffer.extend(make_episode(0, 20))
    buffer.extend(make_episode(1, 20, successes=(15,)))
    batch = buffer.sample_finetuning(500, gap=10)
    for key in ("negative", "positive", ("positive_pair", "earlier")):
        assert (batch[key]["step"] >= 1).all(), key
    assert set(batch["negative", "step"].tolist()) == set(range(1, 21))
    assert set(batch["positive", "step"].tolist()) == set(range(1, 17))


def test_directional_release_option_scores_contrast_at_plain_position():
    torch.manual_seed(2)
    dim = 6
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional=None,
                            directional="d4")
    goal = torch.randn(dim)
    thesis = DirectionalLoss(reward, goal)
    release = DirectionalLoss(reward, goal, same_position=False)
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
    from test_replay import make_episode

    buffer = EpisodeReplayBuffer(capacity=300, history=2)
    reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional="furl",
                            directional="d3")
    positional = PositionalRankingLoss(reward, torch.randn(4))
    directional = DirectionalLoss(reward, torch.randn(4))
    buffer.extend(make_episode(0, 20))
    batch = buffer.sample_finetuning(16, gap=10)
    assert int(positional(batch)["stage"]) == 1 and int(directional(batch)["stage"]) == 1
    buffer.extend(make_episode(1, 20, successes=(15,)))
    batch = buffer.sample_finetuning(16, gap=10)
    out = positional(batch)
    assert int(out["stage"]) == 2 and {"loss_pos_neg", "loss_pos_pos"} <= set(out.keys())
    assert int(directional(batch)["stage"]) == 2


def test_losses_need_heads():
    reward = TemporalReward(4, torch.randn(4), torch.randn(4), positional="liv")
    with pytest.raises(ValueError, match="positional"):
        PositionalRankingLoss(reward, torch.zeros(4))
    with pytest.raises(ValueError, match="directional"):
        DirectionalLoss(reward, torch.zeros(4))
