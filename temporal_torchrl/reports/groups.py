"""Run directories of ``recipes/sac_temporal.py``: finding them, reading them, grouping them.

A run directory is any directory holding a ``config.json`` (the recipe writes it before the
first episode); a sweep directory is any tree that contains run directories. A run's episodes
come from its ``episodes.csv``, one row per finished episode, which a killed or still running
run has too; ``summary.json`` is there only once the run has finished.

Runs are grouped into *configurations*: runs whose configs are equal once the seed, the task and
the keys about the process that ran them (:data:`NON_CONFIGURATION_KEYS`) are left out. Seeds of one
configuration are averaged; runs that differ in anything else never are. A run found twice with
the same episodes (one run copied into two studies' folders) counts once.

Example:
    >>> runs = find_runs(["runs/door-open"])                       # doctest: +SKIP
    >>> [(group.label, len(group.runs)) for group in group_runs(runs)]  # doctest: +SKIP
    [('FuRL ρ=0.05', 4), ('FuRL ρ=1', 4)]
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from temporal_torchrl.envs import EVALUATION_TASKS
from temporal_torchrl.rewards.config import has_vlm_reward, none_or_name, with_moved_options
from temporal_torchrl.runs import DEVICE_KEYS, PROCESS_KEYS, RESUMABLE_KEYS
from temporal_torchrl.runs.layout import (
    flatten,
    protocol_name,
)
from temporal_torchrl.runs.readers import RUN_KEYS, Run
from temporal_torchrl.runs.resume import BEFORE_THE_KEY, FRAME_KEYS

#: Config keys that do not make two runs different configurations: those about the process
#: that ran a run (where it wrote, whether it resumed, when it stopped, its progress bar and
#: threads), the keys a resume may extend (a run extended with ``train.episodes`` is the same
#: run, longer), the devices, and, below, compilation and the logger. Runs that differ only in
#: these (and the seed) are one configuration.
NON_CONFIGURATION_KEYS = (*PROCESS_KEYS, *RESUMABLE_KEYS, *DEVICE_KEYS)
#: Key prefixes left out like :data:`NON_CONFIGURATION_KEYS` (``logger.*``, ``compile.*``).
PROCESS_PREFIXES = ("logger.", "compile.")
#: Last key component left out wherever it appears (a sweep launcher's ``runs_dir``).
PROCESS_LEAVES = ("runs_dir",)

def is_process_key(key: str) -> bool:
    """Whether ``key`` (dotted) is about the process rather than the run (see module doc)."""
    return (key in NON_CONFIGURATION_KEYS or key.startswith(PROCESS_PREFIXES)
            or key.rsplit(".", 1)[-1] in PROCESS_LEAVES)


def configuration_settings(run: Run) -> dict[str, Any]:
    """The run's flattened config without the seed, the task, the process keys, empty groups
    (``reward.options: {}`` says what a run older than the key says by lacking it) and the keys
    nothing read (``eval.*`` without evaluations; the frames' and encoder's keys without a VLM
    reward, since such a run renders nothing), a key it predates at what it meant then
    (``env.goal: fixed``), its reward
    options spelled as now (``reward.window: 8``, which runs saved before the options held,
    says what a run saved since says by ``reward.window: null``:
    :func:`~temporal_torchrl.rewards.config.with_moved_options`)."""
    settings = {key: value for key, value in flatten(with_moved_options(run.config)).items()
                if key not in RUN_KEYS and not is_process_key(key) and value != {}}
    for key, meant in BEFORE_THE_KEY.items():  # a run older than the key meant this
        settings.setdefault(key, meant)
    unread = [key for key in settings if key.startswith("eval.")] \
        if settings.get("eval.every") is None else []
    if not has_vlm_reward(settings.get("reward.positional"), settings.get("reward.directional")):
        unread += [key for key in settings if key.startswith(FRAME_KEYS)]
    return {key: value for key, value in settings.items() if key not in unread}


def _rho(value: float) -> str:
    return f"{value:g}"


def configuration_name(settings: Mapping[str, Any], *, encoder: bool = False,
                       protocol: bool = False) -> str:
    """A thesis-like name: ``SAC``, ``FuRL ρ=0.05``, ``FuRL ρ=1 + D3 λ=4 (b_g)``, ``P2 ρ=0.05
    (b_t)``; the encoder and the protocol added when asked (they vary among the runs shown).

    The baseline is named for the rewards that read it (P1-P4 and the directional ones):
    ``b_g`` generic, ``b_t`` tailored, else the text.
    """
    positional = none_or_name(settings.get("reward.positional"))
    directional = none_or_name(settings.get("reward.directional"))
    parts = []
    if positional is None and directional is None:
        parts.append("SAC")
    else:
        rho = f"ρ={_rho(settings['reward.rho'])}"
        names = {"furl": "FuRL", "liv": "LIV"}
        if positional is not None:
            parts.append(f"{names.get(positional, positional.upper())} {rho}")
        if directional is not None:
            term = f"{directional.upper()} λ={_rho(settings['reward.lambda_'])}"
            parts.append(f"+ {term}" if positional is not None else f"{term} {rho}")
        baseline = settings.get("reward.baseline")
        if uses_baseline(positional, directional):
            parts.append({"generic": "(b_g)", "tailored": "(b_t)"}.get(baseline,
                                                                       f"(b: {baseline!r})"))
        if encoder:
            parts.append(f"[{settings.get('encoder.name')}]")
    if protocol:
        parts.append(f"[{protocol_name(settings.get('train.preload_positives', 0))}]")
    return " ".join(parts)


#: Positional rewards that do not read the baseline text (FuRL, zero-shot LIV).
BASELINE_FREE_POSITIONAL = ("furl", "liv")


def uses_baseline(positional: str | None, directional: str | None) -> bool:
    """Whether the reward reads the baseline text b (P1-P4 and every directional reward)."""
    return directional is not None or (positional is not None
                                       and positional not in BASELINE_FREE_POSITIONAL)


@dataclass(frozen=True)
class RunGroup:
    """The runs of one configuration (all tasks, all seeds).

    Attributes:
        label: the name shown in tables and legends (unique among the groups reported).
        settings: the shared flattened config (:func:`configuration_settings`).
        runs: its runs, sorted by task then seed.
    """

    label: str
    settings: dict[str, Any]
    runs: tuple[Run, ...] = field(repr=False)

    @property
    def tasks(self) -> list[str]:
        return order_tasks({run.task for run in self.runs})

    def runs_for(self, task: str) -> list[Run]:
        return [run for run in self.runs if run.task == task]

    def with_seeds(self, seeds: Iterable[int]) -> RunGroup:
        """The group with only the runs of ``seeds`` (a plan's seeds, without those added
        after looking)."""
        kept = set(seeds)
        return RunGroup(self.label, self.settings,
                        tuple(run for run in self.runs if run.seed in kept))


def planned_runs(groups: Sequence[RunGroup],
                 seeds: Iterable[int]) -> tuple[list[RunGroup], tuple[str, ...]]:
    """``groups`` on a plan's ``seeds`` only (a group left with no run dropped), and the runs
    left out, as added after looking: ``"SAC, drawer-open, seed 4"``."""
    kept = set(seeds)
    after = tuple(f"{group.label}, {run.task}, seed {run.seed}" for group in groups
                  for run in group.runs if run.seed not in kept)
    planned = [group.with_seeds(kept) for group in groups]
    return [group for group in planned if group.runs], after


def missing_seeds(seeds: Iterable[int], planned: Iterable[int] | None) -> tuple[int, ...]:
    """The ``planned`` seeds (a plan's, in order) not among the ``seeds`` run; none without a
    plan. A cell with one missing is still running: shown, not judged."""
    if planned is None:
        return ()
    have = set(seeds)
    return tuple(seed for seed in planned if seed not in have)


def task_order(task: str) -> tuple[int, str]:
    """Sort key: the thesis's six tasks in its order, then any other task alphabetically."""
    return ((EVALUATION_TASKS.index(task), "") if task in EVALUATION_TASKS
            else (len(EVALUATION_TASKS), task))


def order_tasks(tasks: Iterable[str]) -> list[str]:
    """``tasks`` without repeats, in :func:`task_order`."""
    return sorted(set(tasks), key=task_order)


def _canonical(value: Any) -> Any:
    """``1.0`` and ``1`` alike (``reward.rho=1`` on the command line, ``1.0`` in a preset)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, list | tuple):
        return [_canonical(each) for each in value]
    return value


def _frozen(settings: Mapping[str, Any]) -> str:
    return json.dumps({key: _canonical(value) for key, value in settings.items()},
                      sort_keys=True)


def _same(first: Any, second: Any) -> bool:
    if isinstance(first, float) or isinstance(second, float):
        return (isinstance(first, int | float) and isinstance(second, int | float)
                and math.isclose(first, second))
    return first == second


def distinguishing_keys(settings: Sequence[Mapping[str, Any]]) -> list[str]:
    """The keys whose values are not the same in all of ``settings`` (missing counts)."""
    keys = sorted(set().union(*settings)) if settings else []
    missing = object()
    return [key for key in keys
            if any(not _same(each.get(key, missing), settings[0].get(key, missing))
                   for each in settings[1:])]


def group_runs(runs: Sequence[Run]) -> list[RunGroup]:
    """Group ``runs`` by configuration (see module doc), with unique thesis-like labels.

    Raises ``ValueError`` when two runs share configuration, task and seed but not their
    episodes: averaging both would count that seed twice. (Copies of one run count once.)
    """
    by_settings: dict[str, list[Run]] = {}
    for run in runs:
        by_settings.setdefault(_frozen(configuration_settings(run)), []).append(run)
    settings = [configuration_settings(members[0]) for members in by_settings.values()]
    # SAC reads no embedding, so its encoder.name says nothing about it.
    several_encoders = len({each.get("encoder.name") for each in settings if has_vlm_reward(
        each.get("reward.positional"), each.get("reward.directional"))}) > 1
    several_protocols = len({each.get("train.preload_positives") for each in settings}) > 1
    labels = [configuration_name(each, encoder=several_encoders, protocol=several_protocols)
              for each in settings]
    for label in set(labels):
        clashing = [index for index, each in enumerate(labels) if each == label]
        if len(clashing) > 1:
            keys = distinguishing_keys([settings[index] for index in clashing])
            for index in clashing:
                values = ", ".join(f"{key}={settings[index].get(key)}" for key in keys)
                labels[index] = f"{label} [{values}]"
    groups = []
    for label, each, members in zip(labels, settings, by_settings.values(), strict=True):
        members = sorted(members, key=lambda run: (task_order(run.task), run.seed))
        seen: dict[tuple[str, int], Run] = {}
        for run in members:
            other = seen.setdefault((run.task, run.seed), run)
            if other.path != run.path and other.successes != run.successes:
                raise ValueError(f"{other.path} and {run.path} are the same configuration, task "
                                 f"and seed ({run.task}, seed {run.seed}) with different "
                                 "episodes; averaging both would count that seed twice. Report "
                                 "one of them (pass the directories to use).")
        # A run found twice with the same episodes is one run copied into two studies.
        groups.append(RunGroup(label, each, tuple(seen.values())))
    return sorted(groups, key=_thesis_order)


def _thesis_order(group: RunGroup) -> tuple:
    """SAC first, then by positional and directional reward, rho, lambda, as the thesis."""
    settings = group.settings
    positional = none_or_name(settings.get("reward.positional")) or ""
    directional = none_or_name(settings.get("reward.directional")) or ""
    vlm = has_vlm_reward(settings.get("reward.positional"), settings.get("reward.directional"))
    return (vlm, positional != "furl", positional, directional,
            settings.get("reward.rho", 0) if vlm else 0,
            settings.get("reward.lambda_", 0) if directional else 0, group.label)
