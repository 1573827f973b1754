"""Reward-finetuning losses for the positional (FuRL) and directional reward heads.

Both are TorchRL :class:`~torchrl.objectives.LossModule` s that read one batch from
:meth:`temporal_torchrl.data.EpisodeReplayBuffer.sample_finetuning`:

- ``"negative"``: states of failed episodes (``embedding`` s_t, ``initial_embedding`` s_0,
  ``previous_embedding`` s_{t-k});
- ``"positive"`` (stage 2 only): positive states of successful episodes;
- ``"positive_pair"`` (stage 2, when a positive run is longer than the gap): ``"later"`` s_i and
  ``"earlier"`` s_{i-gap} from one positive episode.

The stage is read from the batch: stage 2 (thesis 3.1.3.2, 4.3.3.2) starts as soon as the buffer
holds a positive episode, which is when the batch starts to carry ``"positive"``. Each loss owns
only its heads, so ``torch.optim.Adam(loss.parameters(), lr=1e-4)`` is its optimizer.

The rewards are computed by the :class:`~temporal_torchrl.rewards.TemporalReward` itself
(:meth:`~temporal_torchrl.rewards.TemporalReward.positional_reward`,
:meth:`~temporal_torchrl.rewards.TemporalReward.directional_reward`), the same calls the env
transform and the replay relabelling make: a loss holds no copy of the variant, alpha, projection
or text embeddings, so it can never drift from the reward the agent is trained on.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from temporal_torchrl.rewards import DIRECTIONAL, TemporalReward

#: The release's optimizer settings for the heads (prior-implementations.md).
HEADS_LEARNING_RATE = 1e-4


def ranking_loss(preferred: Tensor, other: Tensor, delta: float) -> Tensor:
    """FuRL's ranking loss l_delta(s_p, s_n) = max(0, r(s_n) - r(s_p) + delta) (thesis 3.1.3)."""
    return torch.relu(other - preferred + delta)


class PositionalRankingLoss(LossModule):
    """FuRL's ranking losses for the positional heads f^P (thesis 3.1.3, eq. 3.1-3.4).

    Stage 1 (negatives only), eq. 3.1 with the release's l2 margin: for every pair (i, j) of the
    batch with ``||s_i - s_g|| - ||s_j - s_g|| < -l2_margin`` (s_i clearly closer to the goal
    image embedding s_g), ``l_delta(s_i, s_j)``; summed over j, averaged over i.

    Stage 2: ``L = L_pos-neg + L_pos-pos`` (eq. 3.2-3.4), each the mean over the batch of
    ``l_delta(s^p, s^n)`` and ``l_delta(s^p_i, s^p_{i-gap})``. The stage-1 term is dropped.

    Args:
        reward: the :class:`TemporalReward` whose positional heads are trained (its variant,
            goal and baseline text embeddings, alpha and projection are used as they are).
        goal_image_embedding: s_g ``[D]``, see :func:`temporal_torchrl.data.goal_image_embedding`.
        delta: ranking margin (0.1).
        l2_margin: how much closer to s_g a negative must be to be preferred (0.2).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from temporal_torchrl.rewards import TemporalReward
        >>> D = 8
        >>> reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="furl")
        >>> loss = PositionalRankingLoss(reward, torch.randn(D))
        >>> states = TensorDict({"embedding": torch.randn(16, D),
        ...                      "initial_embedding": torch.randn(16, D),
        ...                      "previous_embedding": torch.randn(16, D)}, [16])
        >>> out = loss(TensorDict({"negative": states}, [16]))
        >>> out["loss_positional"].requires_grad, int(out["stage"])
        (True, 1)
    """

    #: The key of the loss to minimise in the output.
    loss_key = "loss_positional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *,
                 delta: float = 0.1, l2_margin: float = 0.2) -> None:
        super().__init__()
        if reward.positional_heads is None:
            raise ValueError(f"reward.positional={reward.positional!r} has no trainable heads; "
                             "a positional ranking loss needs furl or p1-p4.")
        self.heads = reward.positional_heads
        _reference(self, reward)
        self.delta = delta
        self.l2_margin = l2_margin
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())

    def positional_reward(self, states: TensorDictBase) -> Tensor:
        """r^VLM_P of a batch of states (with gradients into the heads)."""
        return self.reward.positional_reward(states["embedding"], states["initial_embedding"],
                                             states["previous_embedding"])

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch: ``loss_positional`` (to minimise), the parts, and ``stage``."""
        zero = self.goal_image_embedding.new_zeros(())
        parts = {}
        stage = 2 if "positive" in tensordict.keys() else 1
        negative = tensordict.get("negative", None)
        rewards_negative = self.positional_reward(negative) if negative is not None else None
        if stage == 1 and negative is not None:
            distance = (negative["embedding"] - self.goal_image_embedding).norm(dim=-1)
            closer = (distance.unsqueeze(1) - distance.unsqueeze(0)) < -self.l2_margin
            pairwise = ranking_loss(rewards_negative.unsqueeze(1), rewards_negative.unsqueeze(0),
                                    self.delta)
            parts["loss_neg_neg"] = (pairwise * closer).sum(1).mean()
        if stage == 2:
            rewards_positive = self.positional_reward(tensordict["positive"])
            if rewards_negative is not None:
                parts["loss_pos_neg"] = ranking_loss(rewards_positive, rewards_negative,
                                                     self.delta).mean()
            pair = tensordict.get("positive_pair", None)
            if pair is not None:
                parts["loss_pos_pos"] = ranking_loss(self.positional_reward(pair["later"]),
                                                     self.positional_reward(pair["earlier"]),
                                                     self.delta).mean()
        total = sum(parts.values(), zero)
        out = {name: value.detach() for name, value in parts.items()}
        out["loss_positional"] = total
        out["stage"] = torch.tensor(stage)
        return TensorDict(out, [])


class DirectionalLoss(LossModule):
    """Finetuning loss of the directional heads f^D (thesis 4.3.3); no margin.

    Stage 1, on negative states: ``L^D_neg = r_D(s_t, Δs_t) - r_D(s_t, Δ̂s_t)`` with the observed
    direction Δs_t = s_t - s_{t-k} and the direction towards the goal image embedding
    Δ̂s_t = s_g - s_t, both at the position s_t (batch means of each term).
    Stage 2 adds, on positive states, ``L^D_pos = r_D(s_t, Δ̄s_t) - r_D(s_t, Δs_t)`` with the
    opposite direction Δ̄s_t = s_{t-k} - s_t. The buffer never labels an episode's reset frame s_0
    (as in the reference implementations), so every observed direction is that of a real step.

    Args:
        reward: the :class:`TemporalReward` whose directional heads are trained.
        goal_image_embedding: s_g ``[D]``.
        same_position: ``True`` (default, the thesis text): the towards-goal and opposite terms
            use the variant's own position part at s_t, like the observed term. ``False``
            reproduces the thesis's release, where D4 and D5 score those two terms with the
            plain position n(s_t) (D3's input) while the observed term keeps D4's n(s_t - s_0)
            or D5's goal-baseline position. D1-D3 are the same either way.
    """

    #: The key of the loss to minimise in the output.
    loss_key = "loss_directional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *,
                 same_position: bool = True) -> None:
        super().__init__()
        if reward.directional_heads is None:
            raise ValueError("reward.directional=None: a directional loss needs one of "
                             f"{', '.join(DIRECTIONAL)}.")
        self.heads = reward.directional_heads
        _reference(self, reward)
        self.same_position = same_position
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())

    def directional_reward(self, direction_end: Tensor, direction_start: Tensor,
                           states: TensorDictBase, position: Tensor | None = None,
                           variant: str | None = None) -> Tensor:
        """r_D of the direction ``direction_end - direction_start`` at ``position``."""
        return self.reward.directional_reward(direction_end, direction_start,
                                              states["initial_embedding"], position=position,
                                              variant=variant)

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch: ``loss_directional`` (to minimise), the parts, and ``stage``."""
        # The release scores the contrasted direction at the plain position n(s_t): D3's input.
        variant = self.reward.directional
        contrast_variant = (None if self.same_position or variant in ("d1", "d2") else "d3")
        parts = {}
        stage = 2 if "positive" in tensordict.keys() else 1
        negative = tensordict.get("negative", None)
        if negative is not None:
            s_t, s_tk = negative["embedding"], negative["previous_embedding"]
            observed = self.directional_reward(s_t, s_tk, negative)
            towards_goal = self.directional_reward(
                self.goal_image_embedding.expand_as(s_t), s_t, negative, position=s_t,
                variant=contrast_variant)
            parts["loss_negative"] = (observed - towards_goal).mean()
        if stage == 2:
            positive = tensordict["positive"]
            s_t, s_tk = positive["embedding"], positive["previous_embedding"]
            observed = self.directional_reward(s_t, s_tk, positive)
            opposite = self.directional_reward(s_tk, s_t, positive, position=s_t,
                                               variant=contrast_variant)
            parts["loss_positive"] = (opposite - observed).mean()
        total = sum(parts.values(), self.goal_image_embedding.new_zeros(()))
        out = {name: value.detach() for name, value in parts.items()}
        out["loss_directional"] = total
        out["stage"] = torch.tensor(stage)
        return TensorDict(out, [])


def _reference(loss: LossModule, reward: TemporalReward) -> None:
    # Referenced, not registered as a submodule: the loss's parameters and state_dict stay its
    # own heads (one optimizer per loss), while the reward's variant, text embeddings, alpha and
    # projection are read at every call.
    loss.__dict__["reward"] = reward
