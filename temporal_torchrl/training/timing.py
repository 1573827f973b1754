"""Where a run's time goes: seconds per phase of the training loop, with TorchRL's ``timeit``.

The recipe times each phase as TorchRL's SAC recipe does, under ``timeit("time/<phase>")``:

- ``env_step``: one vector step from the collector: the policy, the simulator, rendering, the
  embedding and the temporal reward (the env's transforms);
- ``replay_sample``: drawing a SAC batch from the replay, its relabelling included;
- ``relabel``: of which the reward heads' relabelling of the batch
  (:class:`~temporal_torchrl.transforms.TemporalRewardTransform` on stored data);
- ``sac_update``: the SAC update (and the relay agent's, when relay exploration is on);
- ``head_update``: the reward heads' finetuning step;
- ``episode_end``: an ended episode labelled, inserted, written to disk and logged;
- ``checkpoint``: writing the checkpoint;
- ``evaluation``: the periodic evaluation of the deterministic policy (``eval.every``);
- ``logging``: the training metrics' window flushed to the loggers.

:class:`PhaseClock` reads the totals: :meth:`~PhaseClock.window` gives the seconds since its
last call (logged as ``time/<phase>`` in ``metrics.jsonl`` with the training metrics), and
:meth:`~PhaseClock.totals` the seconds since the clock started (``summary.json``'s
``phase_seconds``). A resumed run counts from its resume: the killed process's time is not
known. Phases nest (``relabel`` is part of ``replay_sample``), so they do not add up to the
wall time.

Example:
    >>> from torchrl import timeit
    >>> clock = PhaseClock()
    >>> with timeit("time/env_step"):
    ...     pass
    >>> sorted(clock.window())
    ['time/env_step']
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from torchrl import timeit

PREFIX = "time/"
PHASES = ("env_step", "replay_sample", "relabel", "sac_update", "head_update", "episode_end",
          "checkpoint", "evaluation", "logging")


def timed(iterable: Iterable[Any], phase: str) -> Iterator[Any]:
    """``iterable``'s items, the time of each ``next`` recorded under ``time/<phase>`` (a
    collector's step happens inside ``next``)."""
    iterator, end = iter(iterable), object()
    while True:
        with timeit(PREFIX + phase):
            item = next(iterator, end)
        if item is end:
            return
        yield item


class PhaseClock:
    """Seconds per phase from TorchRL's ``timeit`` registry, since this clock started."""

    def __init__(self) -> None:
        self._start = self._recorded()
        self._logged = dict(self._start)

    @staticmethod
    def _recorded() -> dict[str, float]:
        return {key: seconds for key, seconds in timeit.todict(percall=False).items()
                if key.startswith(PREFIX)}

    def totals(self) -> dict[str, float]:
        """``phase -> seconds`` since the clock started."""
        return {key.removeprefix(PREFIX): seconds - self._start.get(key, 0.0)
                for key, seconds in self._recorded().items()}

    def window(self) -> dict[str, float]:
        """``time/<phase> -> seconds`` since the last call (or the start)."""
        recorded = self._recorded()
        window = {key: seconds - self._logged.get(key, 0.0) for key, seconds in recorded.items()}
        self._logged = recorded
        return window
