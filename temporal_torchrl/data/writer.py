"""The replay's writer: whole episodes, contiguous, never split or half-overwritten."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data.replay_buffers import Writer
from torchrl.data.replay_buffers.storages import Storage


class EpisodeWriter(Writer):
    """Writes one episode's rows (:func:`episode_rows`) per ``extend``, contiguously.

    Each write invalidates every older episode it overlaps as a whole, and stamps the rows with
    an ``"episode"`` id. The first ``permanent_episodes`` episodes are written at the start of the
    storage and never overwritten: the ring wraps to the row after them. The writer keeps the
    bookkeeping the samplers read (which rows are valid, and the row sets derived from them,
    recomputed once per written episode, never per sample); ``version`` counts the writes.

    Args:
        permanent_episodes: how many of the first episodes are permanent (stage 2's preloaded
            experts: ``train.preload_positives``).
    """

    def __init__(self, permanent_episodes: int = 0) -> None:
        super().__init__()
        if isinstance(permanent_episodes, bool) or not isinstance(permanent_episodes, int) \
                or permanent_episodes < 0:
            raise ValueError(f"permanent_episodes={permanent_episodes!r}; expected an integer "
                             ">= 0 (the preloaded expert episodes).")
        self.permanent_episodes = permanent_episodes
        self._empty()

    def register_storage(self, storage: Storage) -> None:
        super().register_storage(storage)
        self._valid = torch.zeros(storage.max_size, dtype=torch.bool)

    def _empty(self, empty_write_count: bool = True) -> None:  # TorchRL's signature
        self._cursor = 0
        self._permanent_rows = 0
        self._next_episode = 0
        # episode id -> (first row, number of rows); only episodes still readable are kept.
        self.episodes: dict[int, tuple[int, int]] = {}
        self._keys: set[str] | None = None
        if self._storage is not None:
            self._valid = torch.zeros(self._storage.max_size, dtype=torch.bool)
        self.version = 0
        self._derived = None

    @property
    def capacity(self) -> int:
        return self._storage.max_size

    def add(self, data: Any) -> int:
        raise RuntimeError("EpisodeWriter writes whole episodes: extend the buffer with the rows "
                           "of one episode (episode_rows(rollout)), not with a single row.")

    def extend(self, data: TensorDictBase) -> torch.Tensor:
        length = data.shape[0] if data.ndim == 1 else 0
        if length < 2 or "step" not in data.keys():
            hint = (" It looks like a rollout: insert episode_rows(rollout)."
                    if "next" in data.keys() else "")
            raise ValueError(f"extend takes the rows of one episode (episode_rows(rollout): "
                             f"[T + 1] with T >= 1); got shape {tuple(data.shape)} with keys "
                             f"{sorted(data.keys())}.{hint}")
        keys = set(data.keys()) - {"episode"}
        if self._keys is not None and keys != self._keys:
            raise ValueError(
                f"an episode with keys {sorted(keys)} does not match the buffer's "
                f"{sorted(self._keys)}; every episode must carry the same keys (embed all of "
                "them with the same encoder, or none of them).")
        permanent = self._next_episode < self.permanent_episodes
        if permanent and self._cursor + length > self.capacity:
            raise ValueError(f"permanent episodes fill more than capacity={self.capacity} rows; "
                             "raise the buffer capacity.")
        if length > self.capacity - self._permanent_rows:
            raise ValueError(f"an episode of {length} rows does not fit in capacity="
                             f"{self.capacity} ({self._permanent_rows} rows hold permanent "
                             "episodes); raise the buffer capacity.")
        start = self._cursor if self._cursor + length <= self.capacity else self._permanent_rows
        index = torch.arange(start, start + length)
        self._invalidate_overlapping(start, start + length)
        episode_id = self._next_episode
        data = data.clone(False)
        data["episode"] = torch.full((length,), episode_id, dtype=torch.int64,
                                     device=data.device)
        self._storage.set(index, data)
        self._valid[start:start + length] = True
        self._keys = keys
        self.episodes[episode_id] = (start, length)
        self._next_episode += 1
        self._cursor = start + length
        if permanent:
            self._permanent_rows = self._cursor
        self.version += 1
        self._derived = None
        return index

    def _invalidate_overlapping(self, start: int, stop: int) -> None:
        for episode_id, (first, length) in list(self.episodes.items()):
            if first < stop and start < first + length:
                self._valid[first:first + length] = False
                del self.episodes[episode_id]

    def columns(self) -> TensorDictBase:
        """The stored rows as one TensorDict of views (no copy), rows ``0 .. len - 1``."""
        return self._storage.get(slice(None))

    def rows(self) -> dict[str, torch.Tensor]:
        """The sampleable transitions, cached per write (CPU ``int32`` tensors):
        ``transitions`` (valid rows that are not an episode's last) and their ``steps``."""
        if self._derived is None:
            self._derived = self._derive()
        return self._derived

    def _derive(self) -> dict[str, torch.Tensor]:
        if not self.episodes:
            empty = torch.zeros(0, dtype=torch.int32)
            return {"transitions": empty, "steps": empty}
        columns = self.columns().select("last", "step").cpu()
        # int32 rows and steps: a 1,000,000-row buffer keeps 8 MB of index sets, not 16.
        transitions = torch.nonzero(self._valid[:columns.shape[0]] & ~columns["last"])
        transitions = transitions.reshape(-1).int()
        return {"transitions": transitions, "steps": columns["step"][transitions].int()}

    @property
    def valid(self) -> torch.Tensor:
        """Per storage row: whether it belongs to an episode still stored whole."""
        return self._valid

    @property
    def num_permanent_episodes(self) -> int:
        return min(self._next_episode, self.permanent_episodes)

    def state_dict(self) -> dict[str, Any]:
        first = torch.tensor([first for first, _ in self.episodes.values()], dtype=torch.int64)
        return {"cursor": self._cursor, "permanent_rows": self._permanent_rows,
                "next_episode": self._next_episode,
                "valid": self._valid.clone(),
                "episode_ids": torch.tensor(list(self.episodes), dtype=torch.int64),
                "episode_first": first,
                "episode_length": torch.tensor([n for _, n in self.episodes.values()],
                                               dtype=torch.int64),
                "keys": sorted(self._keys) if self._keys is not None else None}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._cursor = state_dict["cursor"]
        self._permanent_rows = state_dict["permanent_rows"]
        self._next_episode = state_dict["next_episode"]
        self._valid = state_dict["valid"].clone()
        self.episodes = {int(i): (int(f), int(n)) for i, f, n in zip(
            state_dict["episode_ids"], state_dict["episode_first"],
            state_dict["episode_length"], strict=True)}
        self._keys = set(state_dict["keys"]) if state_dict["keys"] is not None else None
        self.version += 1
        self._derived = None

    # TorchRL's Writer interface: ReplayBuffer.dumps / loads save and restore the writer with
    # the storage and the sampler (tests/test_replay.py round-trips a buffer through them).
    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        torch.save(self.state_dict(), path / "episode_writer.pt")

    def loads(self, path: str | Path) -> None:
        self.load_state_dict(torch.load(Path(path) / "episode_writer.pt", weights_only=True))
