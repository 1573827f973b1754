"""SAC with its critics stacked: one batched matmul per layer for all of them, no vmap.

TorchRL's :class:`~torchrl.objectives.SACLoss` evaluates its critics through ``vmap`` (or, with
``deactivate_vmap``, one after the other) on functional parameters held in tensordicts. For the
small MLPs of the thesis's agent (batch 256, two (256, 256) hidden layers) on a CPU, that
machinery costs about as much as the matmuls themselves. :class:`StackedCriticSACLoss` computes
the same losses (SAC v2, the ``l2`` critic loss summed over the critics, TD(0) targets from
target critics) with the critics' weights stacked into ``(num_critics, in, out)`` tensors, so
that each layer of every critic is one ``baddbmm``.
"""

from __future__ import annotations

import copy
import math

import torch
from tensordict import TensorDict, TensorDictBase
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import ProbabilisticActor
from torchrl.modules.distributions.utils import rsample_and_log_prob
from torchrl.objectives import LossModule

from temporal_torchrl.modules import relu


class StackedQValueNetwork(nn.Module):
    """``num_critics`` MLP Q-networks Q_i(s, a) = MLP_i([s, a]), ReLU between layers, their
    weights stacked so that one layer of every critic is one batched matmul.

    Each critic is initialised as :class:`torch.nn.Linear` initialises its layers, from its own
    draws.

    Args:
        num_critics: how many Q-networks (SAC's twin critics: 2).
        in_features: observation plus action features.
        num_cells: the hidden layers' widths.

    Example:
        >>> critics = StackedQValueNetwork(2, in_features=43, num_cells=[256, 256])
        >>> critics(torch.randn(8, 39), torch.randn(8, 4)).shape
        torch.Size([2, 8])
    """

    def __init__(self, num_critics: int, in_features: int, num_cells: list[int]) -> None:
        super().__init__()
        if num_critics < 1:
            raise ValueError(f"num_critics={num_critics} is invalid: pass at least 1 (SAC: 2).")
        sizes = [in_features, *num_cells, 1]
        self.num_critics = num_critics
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in zip(sizes[:-1], sizes[1:], strict=False):
            bound = 1 / math.sqrt(fan_in)  # nn.Linear's default: U(-1/sqrt(fan_in), ...)
            self.weights.append(nn.Parameter(
                torch.empty(num_critics, fan_in, fan_out).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(
                torch.empty(num_critics, 1, fan_out).uniform_(-bound, bound)))

    def forward(self, observation: torch.Tensor, action: torch.Tensor,
                detach_parameters: bool = False) -> torch.Tensor:
        """Q_i(observation, action) of every critic, shape ``(num_critics, *batch)``; with
        ``detach_parameters`` no gradient reaches the weights (SAC's actor loss)."""
        in_features = self.weights[0].shape[1]
        if observation.shape[-1] + action.shape[-1] != in_features:
            raise ValueError(
                f"StackedQValueNetwork: an observation of {observation.shape[-1]} and an action "
                f"of {action.shape[-1]} features for critics built with in_features="
                f"{in_features}; build them with in_features = observation + action size.")
        batch_shape = observation.shape[:-1]
        features = torch.cat([observation, action], -1).reshape(1, -1, in_features)
        last = len(self.weights) - 1
        for layer, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            if detach_parameters:
                weight, bias = weight.detach(), bias.detach()
            # The first layer's input is shared: broadcast it rather than copy it per critic.
            features = torch.baddbmm(bias, features.expand(self.num_critics, -1, -1), weight)
            if layer < last:
                features = relu(features)
        return features.reshape(self.num_critics, *batch_shape)


class StackedCriticSACLoss(LossModule):
    """SAC's losses (Haarnoja et al. 2018, the v2 form without a value network) for a
    tanh-Gaussian actor and stacked critics (:class:`StackedQValueNetwork`), with target
    critics updated by Polyak averaging (:meth:`update_target_critics`).

    For a batch ``(s, a, r, s', terminated)``, with ``a' ~ pi(.|s')`` and ``ã ~ pi(.|s)``
    reparametrised, and ``Q̄`` the target critics:

    - ``loss_qvalue`` = ``mean_batch sum_i (Q_i(s, a) - y)^2``, with
      ``y = r + gamma (1 - terminated) (min_i Q̄_i(s', a') - alpha log pi(a'|s'))``;
    - ``loss_actor`` = ``mean(alpha log pi(ã|s) - min_i Q_i(s, ã))``, the critics' weights
      detached;
    - ``loss_alpha`` = ``mean(-log alpha (log pi(ã|s) + target_entropy))``.

    These are TorchRL's ``SACLoss(num_qvalue_nets=2, loss_function="l2", delay_qvalue=True)``
    with a TD(0) value estimator, computed in the same order from the same random draws
    (``tests/test_sac_loss.py`` checks one against the other).

    Args:
        actor: the policy (a :class:`~torchrl.modules.ProbabilisticActor` whose distribution
            has ``rsample``), reading ``"observation"``.
        critics: the Q-networks; the target critics start as their copy.
        gamma: the discount.
        tau: the target critics' Polyak step: Q̄ <- (1 - tau) Q̄ + tau Q.
        alpha_init: the initial entropy coefficient.
        target_entropy: the entropy that alpha's loss steers towards.

    Example:
        >>> from torchrl.modules import MLP, NormalParamExtractor, TanhNormal
        >>> from tensordict.nn import TensorDictModule
        >>> net = nn.Sequential(MLP(in_features=39, out_features=8, num_cells=[64]),
        ...                     NormalParamExtractor())
        >>> actor = ProbabilisticActor(
        ...     TensorDictModule(net, ["observation"], ["loc", "scale"]),
        ...     in_keys=["loc", "scale"], distribution_class=TanhNormal)
        >>> loss = StackedCriticSACLoss(actor, StackedQValueNetwork(2, 43, [64]), gamma=0.99,
        ...                             tau=0.005, alpha_init=1.0, target_entropy=-2.0)
        >>> batch = TensorDict({"observation": torch.randn(16, 39), "action": torch.rand(16, 4),
        ...     "next": {"observation": torch.randn(16, 39), "reward": torch.randn(16, 1),
        ...              "terminated": torch.zeros(16, 1, dtype=torch.bool)}}, [16])
        >>> losses = loss(batch)
        >>> (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
        >>> loss.update_target_critics()
        >>> sorted(losses.keys())
        ['alpha', 'entropy', 'loss_actor', 'loss_alpha', 'loss_qvalue']
    """

    def __init__(self, actor: ProbabilisticActor, critics: StackedQValueNetwork, *,
                 gamma: float, tau: float, alpha_init: float, target_entropy: float) -> None:
        super().__init__()
        self.actor = actor
        self.critics = critics
        self.target_critics = copy.deepcopy(critics).requires_grad_(False)
        self.log_alpha = nn.Parameter(torch.tensor(math.log(alpha_init)))
        self.gamma, self.tau, self.target_entropy = gamma, tau, target_entropy

    @property
    def in_keys(self) -> list:
        return ["observation", "action", ("next", "observation"), ("next", "reward"),
                ("next", "terminated")]

    def _sample(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        with set_exploration_type(ExplorationType.RANDOM):
            dist = self.actor.get_dist(TensorDict(observation=observation,
                                                  batch_size=observation.shape[:-1]))
        return rsample_and_log_prob(dist)

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        observation, action = tensordict["observation"], tensordict["action"]
        next_observation = tensordict["next", "observation"]
        alpha = self.log_alpha.detach().exp()
        with torch.no_grad():
            next_action, next_log_prob = self._sample(next_observation)
            next_value = (self.target_critics(next_observation, next_action).min(0).values
                          - alpha * next_log_prob)
            reward = tensordict["next", "reward"].squeeze(-1)
            bootstrap = ~tensordict["next", "terminated"].squeeze(-1)
            target = reward + self.gamma * bootstrap * next_value
        if torch.compiler.is_compiling():
            # Two graphs, so that the compiled update draws its noise in the eager order: inductor
            # may schedule the two independent draws (next state's, then this state's) the other
            # way round, even with fallback_random. torch.compiler has no public graph break.
            torch._dynamo.graph_break()
        loss_qvalue = (self.critics(observation, action) - target).pow(2).sum(0).mean()
        new_action, log_prob = self._sample(observation)
        new_value = self.critics(observation, new_action, detach_parameters=True).min(0).values
        loss_actor = (alpha * log_prob - new_value).mean()
        log_prob = log_prob.detach()
        loss_alpha = (-self.log_alpha * (log_prob + self.target_entropy)).mean()
        return TensorDict({"loss_actor": loss_actor, "loss_qvalue": loss_qvalue,
                           "loss_alpha": loss_alpha, "alpha": alpha,
                           "entropy": -log_prob.mean()}, [])

    @torch.no_grad()
    def update_target_critics(self) -> None:
        """One Polyak step of the target critics towards the critics."""
        # One fused kernel over every parameter; torch has no public foreach lerp (torch.optim's
        # Adam calls this one).
        torch._foreach_lerp_(list(self.target_critics.parameters()),
                             list(self.critics.parameters()), self.tau)
