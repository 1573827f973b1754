"""Stored episodes: the rows of every episode inserted into the replay buffer (``replay/``, which a
resume re-inserts in order) and, with ``train.save_positives``, of each successful training
episode (``positives/``, which ``train.positives_from`` preloads into another run). One file an
episode, written whole; read back as TensorDicts."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import torch
from tensordict import TensorDict, TensorDictBase

from temporal_torchrl.runs.checkpoint import START_OVER, UnreadableRunFile
from temporal_torchrl.runs.durable import fsync_directory, write_file
from temporal_torchrl.runs.layout import episode_file


class EpisodeStore:
    """The episode files in ``directory`` (``NNNNNN.pt``, numbered by :func:`episode_file`)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    def path(self, index: int) -> Path:
        return self.directory / episode_file(index)

    def save(self, index: int, rows: TensorDictBase) -> None:
        self.directory.mkdir(exist_ok=True)
        data = rows.cpu().to_dict()
        write_file(self.path(index), lambda file: torch.save(data, file))

    def load(self, index: int) -> TensorDict:
        """Episode ``index``'s rows; ``FileNotFoundError`` when it is not stored."""
        path = self.path(index)
        if not path.is_file():
            raise FileNotFoundError(f"{path} does not exist: no episode {index} in "
                                    f"{self.directory}.")
        data = torch.load(path, weights_only=True)
        return TensorDict(data, [data["step"].shape[0]])

    def indices(self) -> list[int]:
        """The stored episodes' numbers, in order."""
        if not self.directory.is_dir():
            return []
        return sorted(int(path.stem) for path in self.directory.glob("*.pt")
                      if path.stem.isdigit())

    def first(self, count: int) -> Iterator[TensorDict]:
        """The rows of episodes ``0 .. count - 1`` in order; :class:`UnreadableRunFile` naming a
        missing or unreadable one (a resume cannot rebuild the buffer exactly without it)."""
        for index in range(count):
            try:
                rows = self.load(index)
            except Exception as error:  # noqa: BLE001 (any failure to read means the same)
                raise UnreadableRunFile(
                    f"replay episode {self.path(index)} is unreadable ({type(error).__name__}: "
                    f"{error}). A resume rebuilds the replay buffer from the first {count} "
                    "replay episodes, so this run cannot continue exactly without it: restore "
                    f"the file from a backup and resume again, or {START_OVER}.") from error
            yield rows

    def truncate(self, keep_below: int) -> None:
        """Delete the episodes numbered ``keep_below`` or more, and half-written files."""
        if not self.directory.is_dir():
            return
        for path in self.directory.iterdir():
            if (path.stem.isdigit() and int(path.stem) >= keep_below) or path.suffix == ".tmp":
                path.unlink()
        fsync_directory(self.directory)
