"""The reward-head trainer: stage switch, loss values against the equations, the Adam step, and
resuming from its state."""

import copy

import pytest
import torch
import torch.nn.functional as F
from helpers import make_episode
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.training import RewardHeadTrainer

D, DELTA, LR = 4, 0.1, 1e-3


def filled_buffer(gap: int = 5) -> EpisodeReplayBuffer:
    buffer = EpisodeReplayBuffer(capacity=200, k=2, gap=gap)
    buffer.extend(episode_rows(make_episode(0, 20), embedding_dtype=torch.float32))
    return buffer


def make_trainer(buffer: EpisodeReplayBuffer, seed: int = 0) -> RewardHeadTrainer:
    torch.manual_seed(seed)
    reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="furl",
                            directional="d3", k=buffer.k)
    return RewardHeadTrainer(reward, torch.full((D,), 25.0), buffer.finetuning, batch_size=8,
                             lr=LR, delta=DELTA)


def furl_reward(reward: TemporalReward, states) -> torch.Tensor:
    """csim(f_I(s), f_L(g)) (thesis 3.1.3), written out with the heads' own layers."""
    heads = reward.positional_heads
    return F.cosine_similarity(heads.image(states["embedding"]),
                               heads.text(reward.goal_embedding).expand(len(states), -1), dim=-1)


def test_stage_switches_with_the_first_positive_episode():
    buffer = filled_buffer()
    trainer = make_trainer(buffer)
    metrics = trainer.update()
    assert trainer.stage == 1 and metrics["stage"].item() == 1.0
    assert {"loss_positional", "loss_neg_neg", "loss_directional"} <= set(metrics.keys())
    assert "loss_pos_neg" not in metrics.keys()
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,)),
                               embedding_dtype=torch.float32))
    metrics = trainer.update()
    assert trainer.stage == 2 and metrics["stage"].item() == 2.0
    assert {"loss_pos_neg", "loss_pos_pos", "loss_positive"} <= set(metrics.keys())


def test_stage_two_positional_loss_is_the_thesis_ranking_loss():
    """L = mean l_delta(s^p, s^n) + mean l_delta(s^p_i, s^p_(i-gap)), l_delta(a, b) =
    max(0, r(b) - r(a) + delta) (thesis eq. 3.2-3.4), on the batch the trainer draws."""
    buffer = filled_buffer()
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,)),
                               embedding_dtype=torch.float32))
    trainer = make_trainer(buffer)
    reward = trainer.reward
    torch.manual_seed(7)
    batch = buffer.finetuning.sample(8)
    with torch.no_grad():
        positive, negative = furl_reward(reward, batch["positive"]), furl_reward(
            reward, batch["negative"])
        later = furl_reward(reward, batch["positive_pair", "later"])
        earlier = furl_reward(reward, batch["positive_pair", "earlier"])
        pos_neg = torch.clamp(negative - positive + DELTA, min=0).mean()
        pos_pos = torch.clamp(earlier - later + DELTA, min=0).mean()
    torch.manual_seed(7)
    metrics = trainer.update()
    torch.testing.assert_close(metrics["loss_pos_neg"], pos_neg)
    torch.testing.assert_close(metrics["loss_pos_pos"], pos_pos)
    torch.testing.assert_close(metrics["loss_positional"], pos_neg + pos_pos)


def test_one_update_is_one_adam_step_on_each_loss():
    """Adam's first step moves every parameter by lr * g / (|g| + eps) against its gradient,
    the gradient of its own loss alone (the trainer takes one backward of their sum)."""
    buffer = filled_buffer()
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,)),
                               embedding_dtype=torch.float32))
    trainer = make_trainer(buffer)
    before = {id(loss): [parameter.detach().clone() for parameter in loss.parameters()]
              for loss in trainer.losses}
    torch.manual_seed(3)
    batch = buffer.finetuning.sample(8)
    gradients = {id(loss): torch.autograd.grad(loss(batch)[loss.loss_key],
                                               list(loss.parameters()), allow_unused=True)
                 for loss in trainer.losses}
    torch.manual_seed(3)
    trainer.update()
    for loss in trainer.losses:
        moved = 0
        for old, new, gradient in zip(before[id(loss)], loss.parameters(), gradients[id(loss)],
                                      strict=True):
            if gradient is None:
                continue
            expected = old - LR * gradient / (gradient.abs() + 1e-8)
            torch.testing.assert_close(new.detach(), expected, atol=1e-6, rtol=1e-5)
            moved += int((gradient != 0).sum())
        assert moved > 0, loss.loss_key


def test_restored_trainer_continues_like_the_uninterrupted_one():
    buffer = filled_buffer()
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,)),
                               embedding_dtype=torch.float32))
    straight = make_trainer(buffer)
    torch.manual_seed(11)
    for _ in range(3):
        straight.update()
    saved_reward = copy.deepcopy(straight.reward.state_dict())
    saved_trainer = copy.deepcopy(straight.state_dict())
    torch.manual_seed(12)
    expected = straight.update()

    restored = make_trainer(buffer, seed=5)  # other initial heads, then loaded
    restored.reward.load_state_dict(saved_reward)
    restored.load_state_dict(saved_trainer)
    torch.manual_seed(12)
    got = restored.update()
    for key in expected.keys():
        torch.testing.assert_close(got[key], expected[key], msg=key)
    for a, b in zip(straight.reward.parameters(), restored.reward.parameters(), strict=True):
        torch.testing.assert_close(a, b)


def test_a_loss_with_nothing_to_score_leaves_its_heads_and_the_others_train():
    buffer = filled_buffer()
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,)),
                               embedding_dtype=torch.float32))
    trainer = make_trainer(buffer)
    positional, directional = trainer.losses
    # The positional loss sees a batch without states: no part, a constant loss.
    trainer._forwards[0] = lambda batch: positional(TensorDict({}, []))
    before = {loss.loss_key: [p.detach().clone() for p in loss.parameters()]
              for loss in trainer.losses}
    metrics = trainer.update()
    assert "summed_parts" not in metrics.keys() and "loss_pos_neg" not in metrics.keys()
    for old, new in zip(before["loss_positional"], positional.parameters(), strict=True):
        torch.testing.assert_close(new.detach(), old)
    assert any(not torch.equal(old, new.detach()) for old, new in
               zip(before["loss_directional"], directional.parameters(), strict=True))


def test_a_loss_that_scored_parts_without_a_gradient_is_an_error():
    trainer = make_trainer(filled_buffer())
    trainer.reward.positional_heads.requires_grad_(False)
    with pytest.raises(RuntimeError, match=r"PositionalRankingLoss summed 1 part\(s\) into "
                                           r"'loss_positional' but returned it without a "
                                           r"gradient"):
        trainer.update()
