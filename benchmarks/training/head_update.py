"""Section ``head_update`` (``heads``): the reward-head update alone.

FuRL's ranking loss and D3's directional loss, stage 2, batch 256, D = 1024 and 256: the
trainer's update (each loss's terms joined into one reward call per head, one backward of their
sum) against its compute bound, its matmuls alone, and the same two losses scored one term at a
time with one backward per loss.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch
from tensordict import TensorDict

from temporal_torchrl.objectives import ranking_loss
from temporal_torchrl.training import RewardHeadTrainer
from training.bounds import bound_row, counted_flops, matmul_row, matmuls_alone
from training.common import Budget, training_setup

Losses = Callable[[TensorDict], tuple[torch.Tensor, torch.Tensor]]


def term_by_term_update(trainer: RewardHeadTrainer) -> tuple[Callable[[], None], Losses]:
    """The trainer's FuRL and D3 losses (stage 2) scored one term at a time through the
    reward's own calls, one backward and one Adam step per loss: the update, and the two
    losses of a batch."""
    reward = trainer.reward
    positional, directional = trainer.losses
    goal = directional.goal_image_embedding

    def r_p(states: TensorDict) -> torch.Tensor:
        return reward.positional_reward(states["embedding"], states["initial_embedding"],
                                        states["previous_embedding"])

    def r_d(end: torch.Tensor, start: torch.Tensor, states: TensorDict,
            position: torch.Tensor | None = None) -> torch.Tensor:
        return reward.directional_reward(end, start, states["initial_embedding"],
                                         position=position)

    def losses(batch: TensorDict) -> tuple[torch.Tensor, torch.Tensor]:
        negative, positive, pair = batch["negative"], batch["positive"], batch["positive_pair"]
        loss_p = (ranking_loss(r_p(positive), r_p(negative), positional.delta).mean()
                  + ranking_loss(r_p(pair["later"]), r_p(pair["earlier"]),
                                 positional.delta).mean())
        n_t, n_tk = negative["embedding"], negative["previous_embedding"]
        p_t, p_tk = positive["embedding"], positive["previous_embedding"]
        loss_d = (r_d(n_t, n_tk, negative).mean()
                  - r_d(goal.expand_as(n_t), n_t, negative, n_t).mean()
                  + r_d(p_tk, p_t, positive, p_t).mean() - r_d(p_t, p_tk, positive).mean())
        return loss_p, loss_d

    def update() -> None:
        batch = trainer.replay.sample(trainer.batch_size)
        for loss, optimizer in zip(losses(batch), trainer.optimizers, strict=True):
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()

    return update, losses


def heads_rows(tmp: Path, budget: Budget, peak: float) -> list[dict]:
    """The head update at D = 1024 and 256 against its bound at the GEMM rate ``peak``, its
    matmuls alone and :func:`term_by_term_update` (checked to compute the same losses)."""
    rows = []
    for dim in (1024, 256):
        trainer = training_setup(tmp, budget, dim)["trainer"]
        reference, losses = term_by_term_update(trainer)
        batch = trainer.replay.sample(trainer.batch_size)
        joined = [loss(batch)[loss.loss_key] for loss in trainer.losses]
        for value, expected in zip(joined, losses(batch), strict=True):
            torch.testing.assert_close(value, expected, rtol=1e-4, atol=1e-5)
        flops = counted_flops(trainer.update)
        seconds = budget.seconds_per_call(trainer.update)
        reference_seconds = budget.seconds_per_call(reference)
        matmul_seconds = budget.seconds_per_call(matmuls_alone(trainer.update))
        measure = f"reward-head update, FuRL + D3, stage 2, D={dim}, eager (ms)"
        rows += [bound_row(measure, seconds, flops, peak),
                 matmul_row(measure, seconds, matmul_seconds),
                 {"measure": measure, "project": 1000 * seconds,
                  "reference": 1000 * reference_seconds,
                  "reference is": "term by term, one backward per loss",
                  "ratio": reference_seconds / seconds}]
    return rows
