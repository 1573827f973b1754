"""Everything a training run resumes from, as one object: :class:`TrainingState`.

A checkpoint (:class:`~temporal_torchrl.runs.Checkpoint`, its fields typed and versioned) is
:meth:`TrainingState.checkpoint`: the SAC loss
(actor, critics, targets, temperature) and its optimizer, the reward (heads, certainty
references), the reward-head trainer (optimizers, stage), the relay agent and its schedule, the
goal image s_g, the counters (:class:`TrainingProgress`, update credits included), the replay's
capacity and preloaded rows, and the torch, Python and NumPy random generators. The generators are
restored apart (:func:`set_rng_state`), after everything the build draws, so a resumed run goes on
with the numbers the uninterrupted one would have drawn.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from temporal_torchrl.runs import Checkpoint


@dataclass
class UpdateCredits:
    """Updates owed to the env steps taken: ``rate`` updates per env step at any number of envs,
    fractions carried over (``utd_ratio=0.5``: one update every 2 steps)."""

    sac: float = 0.0
    reward: float = 0.0

    def add(self, env_steps: int, sac_rate: float, reward_rate: float) -> tuple[int, int]:
        """Credit ``env_steps`` steps; returns the whole (SAC, reward-head) updates now due,
        which are debited."""
        self.sac += env_steps * sac_rate
        self.reward += env_steps * reward_rate
        due = int(self.sac), int(self.reward)
        self.sac -= due[0]
        self.reward -= due[1]
        return due


@dataclass
class TrainingProgress:
    """The run's counters: finished episodes, env steps, episodes inserted into the replay
    (the preloaded ones included), SAC updates, each episode's success, the last logged training
    metrics and the update credits."""

    episode: int = 0
    env_steps: int = 0
    inserted: int = 0
    updates: int = 0
    successes: list[bool] = field(default_factory=list)
    last_metrics: dict[str, float] = field(default_factory=dict)
    credits: UpdateCredits = field(default_factory=UpdateCredits)


class TrainingState:
    """The modules and counters of a run, saved and restored together (see the module doc).

    Args:
        progress: the counters.
        sac_loss, sac_optimizer: the ``StackedCriticSACLoss`` (it holds the actor, the critics
            and their targets) and its optimizer.
        reward, trainer, relay: the VLM reward, the reward-head trainer and the relay
            exploration, each None when the run has none.
        goal_image: s_g (None without finetuned heads).
        buffer_capacity, expert_rows: the replay's rows and the preloaded positives' share.
    """

    def __init__(self, progress: TrainingProgress, *, sac_loss: nn.Module,
                 sac_optimizer: torch.optim.Optimizer, reward: nn.Module | None = None,
                 trainer: Any | None = None, relay: Any | None = None,
                 goal_image: torch.Tensor | None = None, buffer_capacity: int = 0,
                 expert_rows: int = 0, preloaded: int = 0) -> None:
        self.progress = progress
        self.sac_loss, self.sac_optimizer = sac_loss, sac_optimizer
        self.reward, self.trainer, self.relay = reward, trainer, relay
        self.goal_image = goal_image
        self.buffer_capacity, self.expert_rows, self.preloaded = (buffer_capacity, expert_rows,
                                                                  preloaded)

    def checkpoint(self) -> Checkpoint:
        """The run's checkpoint, of plain tensors and values (``torch.load(weights_only=True)``
        reads it back)."""
        progress = self.progress
        return Checkpoint(
            sac_loss=self.sac_loss.state_dict(), sac_optimizer=self.sac_optimizer.state_dict(),
            reward=self.reward.state_dict() if self.reward is not None else {},
            trainer=self.trainer.state_dict() if self.trainer is not None else {},
            relay=self.relay.state_dict() if self.relay is not None else {},
            goal_image=self.goal_image if self.trainer is not None else None,
            episode=progress.episode, env_steps=progress.env_steps, inserted=progress.inserted,
            updates=progress.updates, successes=list(progress.successes),
            last_metrics=progress.last_metrics,
            credits={"sac": progress.credits.sac, "reward": progress.credits.reward},
            buffer_capacity=self.buffer_capacity, expert_rows=self.expert_rows,
            preloaded=self.preloaded, rng=rng_state())

    def load_checkpoint(self, checkpoint: Checkpoint) -> None:
        """Restore the modules and the counters (the random generators: :func:`set_rng_state`
        with ``checkpoint.rng``, once the build's own draws are done)."""
        if "qvalue_network_params.module.0.weight" in checkpoint.sac_loss:
            raise ValueError(
                "this checkpoint's SAC agent was saved by TorchRL's SACLoss (temporal-torchrl "
                "before its stacked critics, see the CHANGELOG), whose critics this version "
                "cannot load. Resume the run with the release that wrote it, or start it afresh "
                "in a new output_dir.")
        self.sac_loss.load_state_dict(checkpoint.sac_loss)
        self.sac_optimizer.load_state_dict(checkpoint.sac_optimizer)
        for name in ("reward", "trainer", "relay"):
            module = getattr(self, name)
            if module is not None:
                module.load_state_dict(getattr(checkpoint, name))
        restored = progress_from(checkpoint)
        for name in vars(restored):  # in place: the loop holds this progress object
            setattr(self.progress, name, getattr(restored, name))


def progress_from(checkpoint: Checkpoint) -> TrainingProgress:
    """The counters of a checkpoint (:meth:`TrainingState.checkpoint`)."""
    credits = checkpoint.credits
    return TrainingProgress(
        episode=checkpoint.episode, env_steps=checkpoint.env_steps,
        inserted=checkpoint.inserted, updates=checkpoint.updates,
        successes=list(checkpoint.successes), last_metrics=dict(checkpoint.last_metrics),
        credits=UpdateCredits(sac=credits.get("sac", 0.0), reward=credits.get("reward", 0.0)))


def rng_state() -> dict[str, Any]:
    """torch (CPU and every GPU), Python and NumPy generator states, as tensors and plain
    values (``torch.load(..., weights_only=True)`` reads them back)."""
    _, keys, position, has_gauss, cached = np.random.get_state()
    return {"torch": torch.get_rng_state(), "python": random.getstate(),
            "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
            "numpy": {"keys": torch.from_numpy(keys.astype(np.int64)), "position": position,
                      "has_gauss": has_gauss, "cached": cached}}


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if state.get("cuda") and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    random.setstate(state["python"])
    numpy_state = state["numpy"]
    np.random.set_state(("MT19937", numpy_state["keys"].numpy().astype(np.uint32),
                         numpy_state["position"], numpy_state["has_gauss"],
                         numpy_state["cached"]))
