"""The replay's transforms from sampled rows to batches: SAC's transitions and the finetuning's
groups, on the training device."""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs.transforms import Transform


def _embeddings(rows: TensorDictBase, columns: slice | int) -> torch.Tensor:
    return rows["embedding"][..., columns, :].float()


def _to_device(batch: TensorDict, device: torch.device | None) -> TensorDict:
    """``batch`` on ``device``; from the CPU to a GPU through pinned memory, asynchronously."""
    if device is None or batch.device == device:
        return batch
    if batch.device is not None and batch.device.type == "cpu" and device.type == "cuda":
        batch = batch.pin_memory()
    return batch.to(device, non_blocking=True)


class TransitionLayout(Transform):
    """Rows ``[B, 4 (+ K)]`` from :class:`TransitionSampler` -> SAC transitions ``[B]``.

    Keys: ``observation``, ``action``, ``step``, ``episode`` and under ``"next"``:
    ``observation``, ``embedding`` (s_{t+1}), ``initial_embedding`` (s_0),
    ``previous_embedding`` (s_{t+1-k}, s_0 when ``t+1-k <= 0``), with ``window_length``
    ``embedding_window`` (s_{t+2-K} .. s_{t+1}, padded with s_0), ``success``, ``terminated``,
    ``truncated``, ``done`` and ``reward`` (the sparse task reward ``success_{t+1} - 1``, which a
    :class:`~temporal_torchrl.transforms.TemporalRewardTransform` after this one overwrites).
    Embeddings are returned in ``float32``, the batch on ``device`` (None: the storage's).
    """

    def __init__(self, window_length: int | None = None,
                 device: torch.device | str | None = None) -> None:
        super().__init__()
        self.window_length = window_length
        self.device = torch.device(device) if device is not None else None

    def forward(self, rows: TensorDictBase) -> TensorDictBase:
        success = rows["success"][:, 1]
        terminated = rows["terminated"][:, 1]
        truncated = rows["last"][:, 1].unsqueeze(-1)
        following = {"success": success, "terminated": terminated, "truncated": truncated,
                     "done": terminated | truncated, "reward": success.float() - 1.0}
        batch = {"action": rows["action"][:, 0], "step": rows["step"][:, 0].long(),
                 "episode": rows["episode"][:, 0]}
        if "observation" in rows.keys():
            batch["observation"] = rows["observation"][:, 0]
            following["observation"] = rows["observation"][:, 1]
        if "embedding" in rows.keys():
            embeddings = _embeddings(rows, slice(1, None))
            following["embedding"] = embeddings[:, 0]
            following["initial_embedding"] = embeddings[:, 1]
            following["previous_embedding"] = embeddings[:, 2]
            if self.window_length:
                following["embedding_window"] = embeddings[:, 3:]
        batch["next"] = following
        return _to_device(TensorDict(batch, rows.shape[:1], device=rows.device), self.device)


class FinetuningLayout(Transform):
    """Rows ``[G, B, 3 (+ K)]`` from :class:`FinetuningSampler` -> the finetuning batch ``[B]``.

    Sub-TensorDicts ``"negative"``, ``"positive"`` (states) and ``"positive_pair"`` (``"later"``
    s_i and ``"earlier"`` s_{i-gap}), those the sampler drew (``groups``, the sampler's
    :meth:`FinetuningSampler.groups`: the same answer as when it sampled, both read from the
    writer). Each state has ``embedding`` (s_t), ``initial_embedding`` (s_0),
    ``previous_embedding`` (s_{t-k}, clamped to s_0), with ``window_length`` ``embedding_window``
    (s_{t-K+1} .. s_t, padded with s_0; not for the pair's states, which only the positional
    ranking loss reads), ``label``, ``step`` and ``episode``; the batch on ``device`` (None: the
    storage's).
    """

    def __init__(self, groups: Callable[[], tuple[str, ...]],
                 window_length: int | None = None,
                 device: torch.device | str | None = None) -> None:
        super().__init__()
        self.groups = groups
        self.window_length = window_length
        self.device = torch.device(device) if device is not None else None

    def _states(self, rows: TensorDictBase, embeddings: torch.Tensor,
                window: bool) -> TensorDict:
        states = {"embedding": embeddings[:, 0], "initial_embedding": embeddings[:, 1],
                  "previous_embedding": embeddings[:, 2], "label": rows["label"][:, 0],
                  "step": rows["step"][:, 0].long(), "episode": rows["episode"][:, 0]}
        if self.window_length and window:
            states["embedding_window"] = _embeddings(rows, slice(3, None))
        return TensorDict(states, rows.shape[:1], device=rows.device)

    def forward(self, rows: TensorDictBase) -> TensorDictBase:
        batch = TensorDict({}, rows.shape[1:2], device=rows.device)
        # One conversion for every group's states, so the losses join groups as views; the
        # windows (K rows a state) are converted only where a loss reads them.
        embeddings = _embeddings(rows, slice(0, 3))
        group = iter(range(rows.shape[0]))

        def states(window: bool = True) -> TensorDict:
            index = next(group)
            return self._states(rows[index], embeddings[index], window)

        for name in self.groups():
            if name == "positive_pair":
                batch[name] = TensorDict({"later": states(False), "earlier": states(False)},
                                         rows.shape[1:2])
            else:
                batch[name] = states()
        return _to_device(batch, self.device)
