"""Reward-finetuning losses for the positional (FuRL) and directional reward heads.

All are :class:`~temporal_torchrl.objectives.finetuning.base.FinetuningLoss` es (TorchRL
:class:`~torchrl.objectives.LossModule` s) that read one batch from
``EpisodeReplayBuffer.finetuning.sample()`` (:class:`~temporal_torchrl.data.FinetuningSampler`
and :class:`~temporal_torchrl.data.FinetuningLayout`):

- ``"negative"``: states of failed episodes (``embedding`` s_t, ``initial_embedding`` s_0,
  ``previous_embedding`` s_{t-k}, and ``embedding_window`` s_{t-K+1} .. s_t for a reward that
  reads a window);
- ``"positive"`` (stage 2 only): valid positive states of successful episodes (step > gap);
- ``"positive_pair"`` (stage 2, when a positive run is longer than the gap): ``"later"`` s_i and
  ``"earlier"`` s_{i-gap} from one positive episode.

Stage 2 (thesis 3.1.3.2, 4.3.3.2) starts as soon as the replay holds a positive episode; the
losses are told the stage (``loss.stage``) by their caller, the
:class:`~temporal_torchrl.training.RewardHeadTrainer`. Each loss owns only its heads, so
``torch.optim.Adam(loss.parameters(), lr=HEADS_LEARNING_RATE)`` is its optimizer.
:func:`finetuning_losses` builds the losses a reward's registered objectives ask for:
:class:`~.positional.PositionalRankingLoss` (thesis 3.1.3), :class:`~.directional.DirectionalLoss`
(thesis 4.3.3) and, beyond the thesis (section 6.4 proposal), :class:`~.certainty.CertaintyLoss`.

The rewards are computed by the :class:`~temporal_torchrl.rewards.TemporalReward` itself
(:meth:`~temporal_torchrl.rewards.TemporalReward.positional_reward`,
:meth:`~temporal_torchrl.rewards.TemporalReward.directional_reward`), the same calls the env
transform and the replay relabelling make: a loss holds no copy of the variant, alpha, projection
or text embeddings, so it can never drift from the reward the agent is trained on.
"""

from __future__ import annotations

from torch import Tensor

from temporal_torchrl.defaults import DELTA, L2_MARGIN, SAME_POSITION
from temporal_torchrl.objectives.finetuning.base import STAGES, FinetuningLoss
from temporal_torchrl.objectives.finetuning.certainty import (
    CertaintyLoss,
    remember_certainty_references,
)
from temporal_torchrl.objectives.finetuning.directional import DirectionalLoss
from temporal_torchrl.objectives.finetuning.positional import PositionalRankingLoss, ranking_loss
from temporal_torchrl.rewards import TemporalReward, objective_of


def finetuning_losses(reward: TemporalReward, goal_image_embedding: Tensor, *, stage: int,
                      delta: float = DELTA, l2_margin: float = L2_MARGIN,
                      same_position: bool = SAME_POSITION) -> list[FinetuningLoss]:
    """The losses that finetune ``reward``'s heads, by each part's registered objective
    (:func:`~temporal_torchrl.rewards.register_reward`): :class:`PositionalRankingLoss` for a
    positional part with heads, :class:`DirectionalLoss` or :class:`CertaintyLoss` for a
    directional part with heads. Give each its own optimizer over ``loss.parameters()``.

    Args:
        reward: the reward whose heads are trained.
        goal_image_embedding: s_g ``[D]``.
        stage: the stage the losses start in (1 or 2; each loss's ``stage`` changes it).
        delta, l2_margin: of :class:`PositionalRankingLoss`.
        same_position: of :class:`DirectionalLoss`.
    """
    losses: list[FinetuningLoss] = []
    if reward.positional_heads is not None:
        losses.append(PositionalRankingLoss(reward, goal_image_embedding, stage=stage,
                                            delta=delta, l2_margin=l2_margin))
    if reward.directional_heads is not None:
        if objective_of(reward.directional) == "certainty":
            losses.append(CertaintyLoss(reward, goal_image_embedding, stage=stage))
        else:
            losses.append(DirectionalLoss(reward, goal_image_embedding, stage=stage,
                                          same_position=same_position))
    return losses


__all__ = [
    "STAGES",
    "CertaintyLoss",
    "DirectionalLoss",
    "FinetuningLoss",
    "PositionalRankingLoss",
    "finetuning_losses",
    "ranking_loss",
    "remember_certainty_references",
]
