"""Loss modules: SAC with stacked critics, and the reward-finetuning losses of the positional and
directional heads."""

from temporal_torchrl.objectives.finetuning import (
    HEADS_LEARNING_RATE,
    CertaintyLoss,
    DirectionalLoss,
    PositionalRankingLoss,
    finetuning_losses,
    ranking_loss,
    remember_certainty_references,
)
from temporal_torchrl.objectives.sac import StackedCriticSACLoss, StackedQValueNetwork

__all__ = [
    "HEADS_LEARNING_RATE",
    "CertaintyLoss",
    "DirectionalLoss",
    "PositionalRankingLoss",
    "StackedCriticSACLoss",
    "StackedQValueNetwork",
    "finetuning_losses",
    "ranking_loss",
    "remember_certainty_references",
]
