"""TorchRL environment transforms, in pipeline order.

``RenderTransform`` (pixels) -> ``EmbeddingTransform`` (embedding) -> ``EmbeddingHistoryTransform``
(s_0, s_{t-k}, and the window s_{t-K+1} .. s_t for d_sequence) -> ``TemporalRewardTransform``
(r_P, r_D and the total reward). The embedding and reward transforms also run on batches sampled
from a replay buffer.
"""

from temporal_torchrl.transforms.embedding import EmbeddingTransform
from temporal_torchrl.transforms.history import (
    WINDOW_KEY,
    EmbeddingHistoryTransform,
)
from temporal_torchrl.transforms.render import RenderTransform
from temporal_torchrl.transforms.reward import TemporalRewardTransform

__all__ = [
    "WINDOW_KEY",
    "EmbeddingHistoryTransform",
    "EmbeddingTransform",
    "RenderTransform",
    "TemporalRewardTransform",
]
