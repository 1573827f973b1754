"""LIV's objective (temporal_torchrl.objectives.liv) on small hand-made embeddings."""

import math

import pytest
import torch

from temporal_torchrl.objectives.liv import LIVLoss


def _unit(angle: float) -> torch.Tensor:
    return torch.tensor([math.cos(angle), math.sin(angle)])


def test_vip_loss_matches_hand_computation():
    # Two samples in 2-D; the goal is the x axis, so cos(embedding, goal) = cos(angle).
    goal = torch.stack([_unit(0.0), _unit(0.0)])
    initial = torch.stack([_unit(math.pi / 2), _unit(math.pi / 3)])
    current = torch.stack([_unit(math.pi / 3), _unit(math.pi / 4)])
    next_ = torch.stack([_unit(math.pi / 6), _unit(math.pi / 2)])
    gamma = 0.9
    loss = LIVLoss(gamma=gamma, epsilon=0.0).vip_loss(initial, current, next_, goal)

    v0 = [0.0, 0.5]  # cos(pi/2), cos(pi/3)
    v = [0.5, math.sqrt(0.5)]
    v_next = [math.sqrt(3) / 2, 0.0]
    expected = (1 - gamma) * -(sum(v0) / 2) + math.log(
        sum(math.exp(-(-1.0 + gamma * vn - vc)) for vc, vn in zip(v, v_next, strict=True)) / 2
    )
    assert loss.item() == pytest.approx(expected, rel=1e-5)


def test_vip_loss_prefers_values_that_increase_towards_the_goal():
    goal = _unit(0.0).expand(3, 2)
    initial = _unit(1.5).expand(3, 2)
    towards = LIVLoss().vip_loss(initial, _unit(1.0).expand(3, 2), _unit(0.5).expand(3, 2), goal)
    away = LIVLoss().vip_loss(initial, _unit(0.5).expand(3, 2), _unit(1.0).expand(3, 2), goal)
    assert towards < away


def test_vip_loss_is_scale_invariant_cosine():
    goal, initial, current, next_ = torch.randn(4, 5, 8).unbind(0)
    loss = LIVLoss()
    assert loss.vip_loss(initial, current, next_, goal).item() == pytest.approx(
        loss.vip_loss(3 * initial, 0.5 * current, 2 * next_, 7 * goal).item(), rel=1e-5)


def test_contrastive_loss_small_when_aligned_and_larger_when_shuffled():
    embeddings = torch.eye(4) * 5
    loss = LIVLoss(temperature=0.1)
    aligned = loss.contrastive_loss(embeddings, embeddings)
    shuffled = loss.contrastive_loss(embeddings, embeddings[torch.tensor([1, 2, 3, 0])])
    assert aligned.item() < 1e-3
    assert shuffled.item() > 5.0


def test_contrastive_loss_treats_same_task_entries_as_positives():
    # Two videos of task 0 and one of task 1: texts of the same task are identical.
    goals = torch.tensor([[1.0, 0.0], [1.0, 0.1], [0.0, 1.0]])
    texts = torch.tensor([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    loss = LIVLoss(temperature=0.05)
    with_tasks = loss.contrastive_loss(goals, texts, torch.tensor([0, 0, 1]))
    without_tasks = loss.contrastive_loss(goals, texts)
    assert with_tasks.item() < 0.01
    assert without_tasks.item() > 0.3  # duplicate texts act as false negatives


def test_forward_returns_weighted_sum_and_gradients():
    torch.manual_seed(0)
    embeddings = [torch.randn(6, 8, requires_grad=True) for _ in range(5)]
    loss = LIVLoss(image_goal_weight=0.5, text_goal_weight=2.0, contrastive_weight=0.25)
    out = loss(*embeddings, task_ids=torch.tensor([0, 0, 1, 1, 2, 2]))
    expected = (0.5 * out["loss_vip_image"] + 2.0 * out["loss_vip_text"]
                + 0.25 * out["loss_contrastive"])
    assert out["loss"].item() == pytest.approx(expected.item(), rel=1e-6)
    assert 0.0 <= out["value_increase_text"].item() <= 1.0
    out["loss"].backward()
    assert all(e.grad is not None and e.grad.abs().sum() > 0 for e in embeddings)


def test_bad_arguments_raise_value_errors():
    with pytest.raises(ValueError, match="gamma"):
        LIVLoss(gamma=1.0)
    with pytest.raises(ValueError, match="shape"):
        LIVLoss()(*(torch.randn(2, 3),) * 4, torch.randn(2, 4))
