"""A run's checkpoint: its schema as one typed object, and the two files that hold it.

:class:`Checkpoint` names every field a checkpoint holds, with its schema version; the recipe
writes one (``TrainingState.checkpoint()``), a resume and the reports read it back through
:class:`CheckpointFiles`, which falls back to the previous checkpoint when the latest cannot be
read. Nothing outside this module spells a checkpoint's keys.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from temporal_torchrl.runs import durable
from temporal_torchrl.runs.layout import CHECKPOINT, PREVIOUS_CHECKPOINT, UNREADABLE_CHECKPOINT

#: The schema version this code writes. Version 1 was written without a ``version`` field.
CHECKPOINT_VERSION = 2


class UnreadableRunFile(RuntimeError):
    """A file a resume needs is missing or unreadable; the message names it and the fix."""


#: How to give up on a run whose files cannot be read.
START_OVER = "start the run over with overwrite=true (this deletes its files)"


@dataclass
class Checkpoint:
    """Everything a run resumes from (``torch.load(..., weights_only=True)`` reads it back).

    Attributes:
        episode, env_steps, inserted, updates: finished episodes, env steps, episodes inserted
            into the replay (the preloaded ones included) and SAC updates.
        successes: each finished episode's success.
        last_metrics: the last logged training metrics.
        credits: the update credits carried over (``{"sac": ..., "reward": ...}``).
        sac_loss, sac_optimizer: the SAC loss's (actor, critics, targets, temperature) and its
            optimizer's state dicts.
        reward, trainer, relay: the VLM reward's, the reward-head trainer's and the relay's
            state dicts (empty when the run has none).
        goal_image: s_g, the embedding of the goal image (None without finetuned heads).
        buffer_capacity, expert_rows, preloaded: the replay's rows, the preloaded positives'
            rows and episodes.
        rng: the torch, Python and NumPy generator states.
        version: the schema version (:data:`CHECKPOINT_VERSION`).
    """

    episode: int
    env_steps: int
    inserted: int
    updates: int
    successes: list[bool]
    last_metrics: dict[str, float]
    sac_loss: dict[str, Any]
    sac_optimizer: dict[str, Any]
    reward: dict[str, Any]
    trainer: dict[str, Any]
    relay: dict[str, Any]
    goal_image: torch.Tensor | None
    buffer_capacity: int
    expert_rows: int
    preloaded: int
    rng: dict[str, Any]
    credits: dict[str, float] = field(default_factory=dict)
    version: int = CHECKPOINT_VERSION

    def to_state(self) -> dict[str, Any]:
        """The plain dict :func:`torch.save` writes (a shallow copy of the fields)."""
        return {item.name: getattr(self, item.name) for item in dataclasses.fields(self)}

    @classmethod
    def from_state(cls, state: dict[str, Any], source: Path | str) -> Checkpoint:
        """The checkpoint in ``state`` (read from ``source``); an error naming the fields it
        lacks or a version this code cannot read."""
        if not isinstance(state, dict):
            raise TypeError(f"it holds a {type(state).__name__}, not a state dict")
        version = state.get("version", 1)
        if version > CHECKPOINT_VERSION:
            raise ValueError(f"{source} has checkpoint schema version {version}; this version of "
                             f"temporal-torchrl reads up to {CHECKPOINT_VERSION}: upgrade it.")
        fields = [item for item in dataclasses.fields(cls) if item.name != "version"]
        missing = [item.name for item in fields if item.name not in state
                   and item.default is dataclasses.MISSING
                   and item.default_factory is dataclasses.MISSING]
        if missing:
            raise ValueError(f"{source} lacks the checkpoint fields {', '.join(missing)}")
        return cls(**{item.name: state[item.name] for item in fields if item.name in state})


class CheckpointFiles:
    """The latest checkpoint of a run directory and the one before it, kept until the new one
    is complete on disk (a kill between the two renames leaves only the previous one)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.latest = directory / CHECKPOINT
        self.previous = directory / PREVIOUS_CHECKPOINT

    def exist(self) -> bool:
        return self.latest.exists() or self.previous.exists()

    def save(self, checkpoint: Checkpoint) -> None:
        temporary = self.directory / (CHECKPOINT + ".tmp")
        state = checkpoint.to_state()
        durable.write_synced(temporary, lambda file: torch.save(state, file))
        if self.latest.exists():
            os.replace(self.latest, self.previous)
        os.replace(temporary, self.latest)
        durable.fsync_directory(self.directory)

    def load(self, *, set_aside: bool = False) -> Checkpoint:
        """The latest readable checkpoint, on the CPU: the latest, else (saying so) the
        previous one; :class:`UnreadableRunFile` when neither can be read. With ``set_aside``
        (a resume), an unreadable latest checkpoint is renamed out of the way, since the next
        checkpoint would otherwise make it the fallback of the next resume."""
        problems = []
        for path in (self.latest, self.previous):
            if not path.exists():
                problems.append(f"{path.name} does not exist")
                continue
            try:
                checkpoint = Checkpoint.from_state(
                    torch.load(path, map_location="cpu", weights_only=True), path)
            except Exception as error:  # noqa: BLE001 (any failure to read means the same)
                problems.append(f"{path.name} is unreadable ({type(error).__name__}: {error})")
                continue
            if problems:
                message = (f"resume: {problems[0]}; continuing from the previous checkpoint, "
                           f"{path} (episode {checkpoint.episode}): the episodes after it run "
                           "again")
                if set_aside and self.latest.exists():
                    os.replace(self.latest, self.directory / UNREADABLE_CHECKPOINT)
                    message += f" (the unreadable one is kept as {UNREADABLE_CHECKPOINT})"
                print(message)
            return checkpoint
        raise UnreadableRunFile(
            f"no readable checkpoint in {self.directory}: {'; '.join(problems)}. Restore "
            f"{CHECKPOINT} from a backup and resume again, or {START_OVER}.")
