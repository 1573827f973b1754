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
:func:`finetuning_losses` builds the losses a reward's registered objectives ask for
(:data:`OBJECTIVE_LOSSES`): :class:`~.positional.PositionalRankingLoss` (thesis 3.1.3),
:class:`~.directional.DirectionalLoss` (thesis 4.3.3) and, beyond the thesis (section 6.4
proposal), :class:`~.certainty.CertaintyLoss`; or the reward's own loss, registered with it
(:func:`~temporal_torchrl.rewards.register_reward`'s ``loss``).

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
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.rewards.registry import registered

#: The loss of each built-in objective
#: (:data:`~temporal_torchrl.rewards.registry.OBJECTIVES_BY_KIND`), for a reward registered
#: without a ``loss`` of its own.
OBJECTIVE_LOSSES: dict[str, type[FinetuningLoss]] = {
    "ranking": PositionalRankingLoss, "directional": DirectionalLoss,
    "certainty": CertaintyLoss}


def loss_class(variant: str) -> type[FinetuningLoss]:
    """The loss that finetunes the heads of the reward registered as ``variant``: its own
    ``loss``, else its objective's (:data:`OBJECTIVE_LOSSES`)."""
    entry = registered(variant)
    return entry.loss if entry.loss is not None else OBJECTIVE_LOSSES[entry.objective]


def finetuning_losses(reward: TemporalReward, goal_image_embedding: Tensor, *, stage: int,
                      delta: float = DELTA, l2_margin: float = L2_MARGIN,
                      same_position: bool = SAME_POSITION) -> list[FinetuningLoss]:
    """The losses that finetune ``reward``'s heads, the positional part's then the directional
    part's, each part with heads by its registration (:func:`loss_class`): its own ``loss``, or
    its objective's, :class:`PositionalRankingLoss`, :class:`DirectionalLoss` or
    :class:`CertaintyLoss`. Give each its own optimizer over ``loss.parameters()``.

    Args:
        reward: the reward whose heads are trained.
        goal_image_embedding: s_g ``[D]``.
        stage: the stage the losses start in (1 or 2; each loss's ``stage`` changes it).
        delta, l2_margin: of :class:`PositionalRankingLoss` (and of a loss that takes them).
        same_position: of :class:`DirectionalLoss` (and of a loss that takes it).
    """
    settings = {"delta": delta, "l2_margin": l2_margin, "same_position": same_position}
    return [loss_class(variant).from_settings(reward, goal_image_embedding, stage=stage,
                                              **settings)
            for variant, heads in ((reward.positional, reward.positional_heads),
                                   (reward.directional, reward.directional_heads))
            if heads is not None]


__all__ = [
    "OBJECTIVE_LOSSES",
    "STAGES",
    "CertaintyLoss",
    "DirectionalLoss",
    "FinetuningLoss",
    "PositionalRankingLoss",
    "finetuning_losses",
    "loss_class",
    "ranking_loss",
    "remember_certainty_references",
]
