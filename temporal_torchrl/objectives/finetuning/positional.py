"""FuRL's ranking losses for the positional heads f^P (thesis 3.1.3)."""

from __future__ import annotations

from collections.abc import Callable

from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from temporal_torchrl.defaults import DELTA, L2_MARGIN
from temporal_torchrl.modules import relu
from temporal_torchrl.objectives.finetuning.base import FinetuningLoss, joined
from temporal_torchrl.rewards import TemporalReward

#: The state keys a positional reward reads.
POSITIONAL_KEYS = ("embedding", "initial_embedding", "previous_embedding")


def ranking_loss(preferred: Tensor, other: Tensor, delta: float) -> Tensor:
    """FuRL's ranking loss l_delta(s_p, s_n) = max(0, r(s_n) - r(s_p) + delta) (thesis 3.1.3)."""
    return relu(other - preferred + delta)


class PositionalRankingLoss(FinetuningLoss):
    """FuRL's ranking losses for the positional heads f^P (thesis 3.1.3, eq. 3.1-3.4).

    Stage 1 (negatives only), eq. 3.1 with the release's l2 margin: for every pair (i, j) of the
    batch with ``||s_i - s_g|| - ||s_j - s_g|| < -l2_margin`` (s_i clearly closer to the goal
    image embedding s_g), ``l_delta(s_i, s_j)``; summed over j, averaged over i.

    Stage 2: ``L = L_pos-neg + L_pos-pos`` (eq. 3.2-3.4), each the mean over the batch of
    ``l_delta(s^p, s^n)`` and ``l_delta(s^p_i, s^p_{i-gap})``. The stage-1 term is dropped.
    The rewards of all the batch's groups come from one :meth:`positional_reward` call on the
    groups concatenated: one batch through the heads.

    Args:
        reward: the :class:`TemporalReward` whose positional heads are trained (its variant,
            goal and baseline text embeddings, alpha and projection are used as they are).
        goal_image_embedding: s_g ``[D]``, see :func:`temporal_torchrl.data.goal_image_embedding`.
        stage: 1 or 2 (see :class:`~temporal_torchrl.objectives.finetuning.base.FinetuningLoss`).
        delta: ranking margin (default :data:`~temporal_torchrl.defaults.DELTA`).
        l2_margin: how much closer to s_g a negative must be to be preferred (default
            :data:`~temporal_torchrl.defaults.L2_MARGIN`).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from temporal_torchrl.rewards import TemporalReward
        >>> D = 8
        >>> reward = TemporalReward(D, torch.randn(D), torch.randn(D), directional=None)
        >>> loss = PositionalRankingLoss(reward, torch.randn(D), stage=1)
        >>> states = TensorDict({"embedding": torch.randn(16, D),
        ...                      "initial_embedding": torch.randn(16, D),
        ...                      "previous_embedding": torch.randn(16, D)}, [16])
        >>> out = loss(TensorDict({"negative": states}, [16]))
        >>> out["loss_positional"].requires_grad, int(out["stage"])
        (True, 1)
    """

    loss_key = "loss_positional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *, stage: int,
                 delta: float = DELTA, l2_margin: float = L2_MARGIN) -> None:
        if reward.positional_heads is None:
            raise ValueError(f"reward.positional={reward.positional!r} has no trainable heads; "
                             "a positional ranking loss needs furl or p1-p4.")
        super().__init__(reward, reward.positional_heads, goal_image_embedding, stage=stage)
        self.delta = delta
        self.l2_margin = l2_margin

    def positional_reward(self, states: TensorDictBase) -> Tensor:
        """r^VLM_P of a batch of states (with gradients into the heads)."""
        return self.reward.positional_reward(states["embedding"], states["initial_embedding"],
                                             states["previous_embedding"])

    def terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The terms for one batch (``loss_positional`` is their sum): ``loss_neg_neg`` in
        stage 1; ``loss_pos_neg`` and ``loss_pos_pos`` in stage 2."""
        groups = self.groups(tensordict)
        rewards = _split_call(self.positional_reward, groups, POSITIONAL_KEYS)
        parts = {}
        if self.stage == 1 and "negative" in rewards:
            distance = (groups["negative"]["embedding"]
                        - self.goal_image_embedding).norm(dim=-1)
            closer = (distance.unsqueeze(1) - distance.unsqueeze(0)) < -self.l2_margin
            pairwise = ranking_loss(rewards["negative"].unsqueeze(1),
                                    rewards["negative"].unsqueeze(0), self.delta)
            parts["loss_neg_neg"] = (pairwise * closer).sum(1).mean()
        if self.stage == 2:
            if "positive" in rewards and "negative" in rewards:
                parts["loss_pos_neg"] = ranking_loss(rewards["positive"], rewards["negative"],
                                                     self.delta).mean()
            if "later" in rewards:
                parts["loss_pos_pos"] = ranking_loss(rewards["later"], rewards["earlier"],
                                                     self.delta).mean()
        return parts


def _split_call(function: Callable[[TensorDictBase], Tensor],
                groups: dict[str, TensorDictBase], keys: tuple[str, ...]) -> dict[str, Tensor]:
    """``function`` of every group, called once on the groups' ``keys`` concatenated: one batch
    through the heads instead of one per group (the heads treat each state on its own)."""
    if not groups:
        return {}
    if len(groups) == 1:  # stage 1: the negatives alone, nothing to join
        (name, states), = groups.items()
        return {name: function(states)}
    sizes = [states.shape[0] for states in groups.values()]
    batch = TensorDict({key: joined([states[key] for states in groups.values()])
                        for key in keys}, [sum(sizes)])
    values = function(batch).split(sizes)
    return dict(zip(groups, values, strict=True))
