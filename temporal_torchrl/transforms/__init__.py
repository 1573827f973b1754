from temporal_torchrl.transforms.embedding import EmbeddingTransform  # noqa: F401
from temporal_torchrl.transforms.history import EmbeddingHistoryTransform  # noqa: F401
from temporal_torchrl.transforms.render import RenderTransform  # noqa: F401
from temporal_torchrl.transforms.reward import TemporalRewardTransform  # noqa: F401
