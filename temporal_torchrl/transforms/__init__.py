"""TorchRL environment transforms, in pipeline order.

``RenderTransform`` (pixels) -> ``EmbeddingTransform`` (embedding) -> ``EmbeddingHistoryTransform``
(s_0 and s_{t-k}) -> ``TemporalRewardTransform`` (r_P, r_D and the total reward). The embedding
and reward transforms also run on batches sampled from a replay buffer.
"""

from temporal_torchrl.transforms.embedding import EmbeddingTransform
from temporal_torchrl.transforms.history import EmbeddingHistoryTransform
from temporal_torchrl.transforms.render import RenderTransform
from temporal_torchrl.transforms.reward import TemporalRewardTransform

__all__ = [
    "EmbeddingHistoryTransform",
    "EmbeddingTransform",
    "RenderTransform",
    "TemporalRewardTransform",
]
