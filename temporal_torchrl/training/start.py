"""How a training run begins, decided once: afresh, from its checkpoint, or not at all.

:func:`start_run` makes the decision (the run directory's checks, the saved config continued,
the checkpoint read and the run's files cut back to it); the :class:`RunStart` it returns is
then asked at each point where the two starts differ, so that the recipe's build reads the same
for both: the replay filled (:meth:`RunStart.fill_replay`), the modules and counters restored
(:meth:`RunStart.restore`) and, last, the random generators (:meth:`RunStart.restore_rng`).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase

from temporal_torchrl.configs.rules import validate_recipe_config
from temporal_torchrl.data import EpisodeReplayBuffer
from temporal_torchrl.runs import (
    CONFIG_FILE,
    Checkpoint,
    RunDirectory,
    check_no_conflict,
    resumed_config,
)
from temporal_torchrl.training.state import (
    TrainingProgress,
    TrainingState,
    progress_from,
    set_rng_state,
)


@dataclass
class RunStart:
    """A run's start.

    Attributes:
        run: its directory (its lock held).
        cfg: the config that runs: the given one on a fresh start, the saved one continued
            (:func:`~temporal_torchrl.runs.resumed_config`) on a resume, validated.
        checkpoint: what it resumes from; None on a fresh start.
        summary: the summary of a run that is already complete (nothing to run), else None.
    """

    run: RunDirectory
    cfg: DictConfig
    checkpoint: Checkpoint | None
    summary: dict[str, Any] | None = None

    @property
    def complete(self) -> bool:
        return self.summary is not None

    def fill_replay(self, buffer: EpisodeReplayBuffer,
                    preloaded: Sequence[TensorDictBase]) -> TrainingProgress:
        """Fill ``buffer`` and return the run's counters: on a fresh start the run directory is
        created and the ``preloaded`` episodes are inserted and saved; on a resume the episodes
        the checkpoint covers are re-inserted in order, as they were."""
        if self.checkpoint is None:
            self.run.create(config=OmegaConf.to_container(self.cfg, resolve=True))
            for index, rows in enumerate(preloaded):
                buffer.extend(rows)
                self.run.save_replay_episode(index, rows)
            return TrainingProgress(inserted=len(preloaded))
        progress = progress_from(self.checkpoint)
        for rows in self.run.replay_episodes(progress.inserted):
            buffer.extend(rows)
        return progress

    def restore(self, state: TrainingState) -> None:
        """Load the checkpoint's modules and counters into ``state`` (a fresh start: nothing)."""
        if self.checkpoint is not None:
            state.load_checkpoint(self.checkpoint)

    def restore_rng(self) -> None:
        """Set the random generators as the checkpoint saved them; called after every random
        draw the build makes, so a resumed run draws what the uninterrupted one would have."""
        if self.checkpoint is not None:
            set_rng_state(self.checkpoint.rng)


def start_run(run: RunDirectory, cfg: DictConfig,
              given_keys: Collection[str] | None) -> RunStart:
    """Decide how the run in ``run`` (whose lock the caller holds) starts (see the module doc).
    ``given_keys``: the keys set on the command line, which alone may change a resumed run's
    resumable keys (None: all of ``cfg``'s do)."""
    check_no_conflict(cfg, run, given_keys)
    run.check(resume=cfg.resume, overwrite=cfg.overwrite)
    if not cfg.resume:
        return RunStart(run, cfg, None)
    saved = run.path / CONFIG_FILE  # the one source of a key the validated cfg did not have
    cfg = validate_recipe_config(resumed_config(cfg, run.path, given_keys), source=(
        f"The run's saved {saved} (written by a version that read the key, or edited): remove "
        "the key from that file to resume it with this version, or resume it with the commit "
        "its provenance.json names."))
    checkpoint = run.resume_state()
    summary = run.summary()
    complete = checkpoint.episode >= cfg.train.episodes and summary
    return RunStart(run, cfg, checkpoint, summary if complete else None)
