"""Loss modules: SAC with stacked critics, and the reward-finetuning losses of the positional and
directional heads (:mod:`.finetuning`: one loss a module, on one base)."""

from temporal_torchrl.defaults import HEADS_LEARNING_RATE
from temporal_torchrl.objectives.finetuning import (
    OBJECTIVE_LOSSES,
    STAGES,
    CertaintyLoss,
    DirectionalLoss,
    FinetuningLoss,
    PositionalRankingLoss,
    finetuning_losses,
    loss_class,
    ranking_loss,
    remember_certainty_references,
)
from temporal_torchrl.objectives.sac import StackedCriticSACLoss, StackedQValueNetwork

__all__ = [
    "HEADS_LEARNING_RATE",
    "OBJECTIVE_LOSSES",
    "STAGES",
    "CertaintyLoss",
    "DirectionalLoss",
    "FinetuningLoss",
    "PositionalRankingLoss",
    "StackedCriticSACLoss",
    "StackedQValueNetwork",
    "finetuning_losses",
    "loss_class",
    "ranking_loss",
    "remember_certainty_references",
]
