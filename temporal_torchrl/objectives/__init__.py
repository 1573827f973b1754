"""Loss modules: the reward-finetuning losses of the positional and directional heads."""

from temporal_torchrl.objectives.finetuning import (
    HEADS_LEARNING_RATE,
    DirectionalLoss,
    PositionalRankingLoss,
    ranking_loss,
)

__all__ = ["HEADS_LEARNING_RATE", "DirectionalLoss", "PositionalRankingLoss", "ranking_loss"]
