"""Section ``sac_update`` (``sac``): the SAC update alone.

Batch 256, (256, 256) networks, fused Adam: the recipe's eager update
(``StackedCriticSACLoss``) against its compute bound and its matmuls alone, against TorchRL's
``SACLoss`` as its docs build it (vmap over the critics, the whole replay batch) and against a
plain-PyTorch twin-critic update; the recipe's update compiled (``compile.enabled``) against it
eager, and both against the bound in alternating rounds, each with its own GEMM rate.
"""

from __future__ import annotations

import copy
import itertools
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch
import torch.nn.functional as F
from omegaconf import DictConfig
from tensordict import TensorDict
from torch import nn
from torchrl.modules import MLP, ValueOperator

from training.bounds import (
    GEMM_FLOPS,
    alternating_seconds,
    bound_row_by_round,
    counted_flops,
    gemm,
    matmul_row,
    matmuls_alone,
    spread,
)
from training.common import ACTION_DIM, OBSERVATION_DIM, Budget, training_setup


class PlainSAC(nn.Module):
    """SAC's update in plain PyTorch, CleanRL's shape: a tanh-Gaussian actor, two critics and
    their targets as separate MLPs, one Adam each for the critics, the actor and the
    temperature; the recipe's sizes, learning rate, gamma, tau and target entropy."""

    def __init__(self, cfg: DictConfig, observation_dim: int = OBSERVATION_DIM,
                 action_dim: int = ACTION_DIM) -> None:
        super().__init__()
        hidden = list(cfg.sac.hidden_sizes)

        def mlp(inputs: int, outputs: int) -> nn.Sequential:
            layers, width = [], inputs
            for size in hidden:
                layers += [nn.Linear(width, size), nn.ReLU()]
                width = size
            return nn.Sequential(*layers, nn.Linear(width, outputs))

        self.actor = mlp(observation_dim, 2 * action_dim)
        self.critics = nn.ModuleList(mlp(observation_dim + action_dim, 1) for _ in range(2))
        self.targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.log_alpha = nn.Parameter(torch.zeros(()))
        self.gamma, self.tau, self.target_entropy = cfg.sac.gamma, cfg.sac.tau, -action_dim / 2
        lr = cfg.sac.lr
        self.optimizers = [torch.optim.Adam(self.critics.parameters(), lr=lr, fused=True),
                           torch.optim.Adam(self.actor.parameters(), lr=lr, fused=True),
                           torch.optim.Adam([self.log_alpha], lr=lr, fused=True)]

    def sample(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A tanh-squashed action and its log-probability."""
        loc, scale = self.actor(observation).chunk(2, -1)
        normal = torch.distributions.Normal(loc, F.softplus(scale) + 1e-4)
        raw = normal.rsample()
        log_prob = (normal.log_prob(raw)
                    - 2 * (torch.log(torch.tensor(2.0)) - raw - F.softplus(-2 * raw))).sum(-1)
        return torch.tanh(raw), log_prob

    def update(self, batch: TensorDict) -> None:
        """One update of the critics, the actor and the temperature, then the targets."""
        observation, action = batch["observation"], batch["action"]
        nxt = batch["next"]
        alpha = self.log_alpha.exp()
        with torch.no_grad():
            next_action, next_log_prob = self.sample(nxt["observation"])
            next_input = torch.cat([nxt["observation"], next_action], -1)
            next_q = torch.min(*(target(next_input) for target in self.targets)).squeeze(-1)
            target_q = nxt["reward"].squeeze(-1) + self.gamma * (
                ~nxt["terminated"].squeeze(-1)) * (next_q - alpha * next_log_prob)
        q_input = torch.cat([observation, action], -1)
        q_loss = sum(F.mse_loss(critic(q_input).squeeze(-1), target_q)
                     for critic in self.critics)
        new_action, log_prob = self.sample(observation)
        pi_input = torch.cat([observation, new_action], -1)
        q_new = torch.min(*(critic(pi_input) for critic in self.critics)).squeeze(-1)
        actor_loss = (alpha.detach() * log_prob - q_new).mean()
        alpha_loss = -(self.log_alpha * (log_prob.detach() + self.target_entropy)).mean()
        for optimizer in self.optimizers:
            optimizer.zero_grad(set_to_none=True)
        q_loss.backward()
        self.optimizers[0].step()
        self.optimizers[0].zero_grad(set_to_none=True)  # the actor loss's critic gradients
        (actor_loss + alpha_loss).backward()
        self.optimizers[1].step()
        self.optimizers[2].step()
        with torch.no_grad():
            for target, critic in zip(self.targets, self.critics, strict=True):
                torch._foreach_lerp_(list(target.parameters()), list(critic.parameters()),
                                     self.tau)


def torchrl_sac_update(cfg: DictConfig, actor: nn.Module) -> Callable[[TensorDict], None]:
    """TorchRL's SACLoss as its docs build it, for a copy of ``actor``: a ValueOperator MLP
    critic vmapped over two copies, the whole batch, a TD(0) estimator, SoftUpdate, fused Adam."""
    from torchrl.objectives import SACLoss, SoftUpdate

    qvalue = ValueOperator(MLP(in_features=OBSERVATION_DIM + ACTION_DIM,
                               num_cells=list(cfg.sac.hidden_sizes), out_features=1,
                               activation_class=nn.ReLU), in_keys=["action", "observation"])
    loss = SACLoss(copy.deepcopy(actor), qvalue, num_qvalue_nets=2, loss_function="l2",
                   alpha_init=cfg.sac.alpha_init, target_entropy=-ACTION_DIM / 2,
                   delay_qvalue=True)
    loss.make_value_estimator(gamma=cfg.sac.gamma)
    target = SoftUpdate(loss, tau=cfg.sac.tau)
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg.sac.lr, fused=True)

    def update(batch: TensorDict) -> None:
        losses = loss(batch)
        (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        target.step()

    return update


def cycling(update: Callable[[TensorDict], object],
            batches: list[TensorDict]) -> Callable[[], object]:
    """``update`` on the next of ``batches`` at every call (sampling not timed)."""
    calls = itertools.count()
    return lambda: update(batches[next(calls) % len(batches)])


def sac_rows(tmp: Path, budget: Budget, mode: str | None) -> list[dict]:
    """The recipe's SAC update, eager and compiled (``mode``), against its bound, its matmuls
    alone, TorchRL's SACLoss and plain PyTorch. Eager, compiled and the GEMM rate are timed in
    ``budget.rounds`` alternating rounds, so that each round's fraction of the bound divides by
    the GEMM rate of the same minutes (the machine's load moves both); the medians are shown."""
    setup = training_setup(tmp, budget, 256)
    batches = [setup["buffer"].sample() for _ in range(8)]
    recipe = cycling(setup["update_sac"], batches)
    flops = counted_flops(recipe)
    matmul_seconds = budget.seconds_per_call(matmuls_alone(recipe))
    torchrl_seconds = budget.seconds_per_call(
        cycling(torchrl_sac_update(setup["cfg"], setup["actor"]), batches))
    plain = PlainSAC(setup["cfg"])
    plain_seconds = budget.seconds_per_call(cycling(plain.update, batches))
    compiled_update = cycling(training_setup(tmp, budget, 256, "compile.enabled=true",
                                             f"compile.mode={mode or 'null'}")["update_sac"],
                              batches)
    start = time.perf_counter()
    for _ in range(3):
        compiled_update()
    compile_seconds = time.perf_counter() - start
    times = alternating_seconds({"eager": recipe, "compiled": compiled_update, "gemm": gemm()},
                                budget.rounds, budget.seconds / 2,
                                min(3, budget.warmup_calls))
    peaks = [GEMM_FLOPS / seconds for seconds in times["gemm"]]
    recipe_seconds, compiled_seconds = (statistics.median(times[key])
                                        for key in ("eager", "compiled"))
    speedups = [e / c for e, c in zip(times["eager"], times["compiled"], strict=True)]
    rounds = len(times["eager"])
    print(f"sac: {flops / 1e9:.3f} GFLOP; compiled in {compile_seconds:.0f} s", flush=True)
    return [
        bound_row_by_round(f"SAC update, recipe, eager, median of {rounds} rounds (ms)",
                           times["eager"], flops, peaks),
        bound_row_by_round(f"SAC update, recipe compiled ({mode}; compile "
                           f"{compile_seconds:.0f} s), median of {rounds} rounds (ms)",
                           times["compiled"], flops, peaks),
        {"measure": f"SAC update, recipe compiled ({mode}), median of {rounds} rounds (ms)",
         "project": 1000 * compiled_seconds, "reference": 1000 * recipe_seconds,
         "reference is": f"the recipe's eager update, alternating (speed-up {spread(speedups)})",
         "ratio": statistics.median(speedups)},
        matmul_row("SAC update, recipe, eager (ms)", recipe_seconds, matmul_seconds),
        {"measure": "SAC update, recipe, eager (ms)", "project": 1000 * recipe_seconds,
         "reference": 1000 * torchrl_seconds,
         "reference is": "TorchRL SACLoss as documented (vmap critics, whole batch)",
         "ratio": torchrl_seconds / recipe_seconds},
        {"measure": "SAC update, recipe, eager (ms)", "project": 1000 * recipe_seconds,
         "reference": 1000 * plain_seconds, "reference is": "plain PyTorch (CleanRL's shape)",
         "ratio": plain_seconds / recipe_seconds},
    ]
