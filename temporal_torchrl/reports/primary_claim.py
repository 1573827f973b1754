"""A registered plan's primary claim, from the runs: X against Y over the tasks, tested once.

The Table 5.12 analysis plan (``docs/results/table_5_12/analysis_plan.md``) fixes the test
before the runs: over every task on which each configuration of the claim has every planned
seed finished, the difference of mean RAS over tasks Δ(X, Y), a stratified permutation test
(:mod:`~temporal_torchrl.reports.statistics`), Holm's correction over the primary pairs, a
95% stratified-bootstrap interval for the size and, as a sensitivity analysis only, the paired
sign-flip test (runs paired by seed, which shares the layout). Secondary pairs get the same
numbers outside Holm's family. Runs of seeds outside the plan (added after looking) enter
nothing here; they are listed as such.

``report.py ... --primary X Y --primary X Z --secondary Y Z --planned-seeds 0 1 2 3`` writes
``primary_claim.md`` and ``.csv``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from temporal_torchrl.reports.aggregate import VALUE, run_value
from temporal_torchrl.reports.groups import RunGroup, planned_runs
from temporal_torchrl.reports.rows import EMPTY_CELL, Column, Table, field_column
from temporal_torchrl.reports.statistics import (
    ABOVE,
    BELOW,
    NOT_RESOLVED,
    SEED,
    holm,
    paired_sign_flip_test,
    stratified_bootstrap_interval,
    stratified_permutation_test,
)

#: The seeds the Table 5.12 plan fixed, when a report names none.
PLANNED_SEEDS = (0, 1, 2, 3)
#: The family-wise level of the primary claim.
ALPHA = 0.05


@dataclass(frozen=True)
class PairTest:
    """X against Y over ``tasks`` (module doc).

    Attributes:
        primary: in Holm's family (else a secondary hypothesis).
        difference: Δ(X, Y) in RAS points.
        low, high: its 95% stratified-bootstrap interval.
        p_value: the stratified permutation test's two-sided p.
        adjusted_p: Holm's adjusted p (primary pairs), else None.
        paired_p: the paired sign-flip test's p (sensitivity only).
    """

    label: str
    baseline: str
    primary: bool
    tasks: tuple[str, ...]
    difference: float
    low: float
    high: float
    p_value: float
    adjusted_p: float | None
    paired_p: float

    @property
    def verdict(self) -> str:
        p = self.adjusted_p if self.primary else self.p_value
        if p >= ALPHA:
            return NOT_RESOLVED
        return ABOVE if self.difference > 0 else BELOW


@dataclass(frozen=True)
class PrimaryClaim:
    """The pairs tested, the planned seeds and the runs left out as added after looking."""

    tests: tuple[PairTest, ...]
    planned_seeds: tuple[int, ...]
    permutations: int
    resamples: int
    after_looking: tuple[str, ...]  # "SAC, drawer-open, seed 4"


def planned_ras(group: RunGroup, planned_seeds: Sequence[int]) -> dict[str, list[float]]:
    """Task -> the RAS of ``group``'s runs of the planned seeds, in seed order, on the tasks
    where every planned seed has one."""
    values = {}
    for task in group.tasks:
        by_seed = {run.seed: run_value(run, "ras") for run in group.runs_for(task)}
        if all(seed in by_seed and by_seed[seed].status == VALUE for seed in planned_seeds):
            values[task] = [by_seed[seed].value for seed in sorted(planned_seeds)]
    return values


def build_primary_claim(groups: Sequence[RunGroup], primary: Sequence[tuple[str, str]],
                        secondary: Sequence[tuple[str, str]], planned_seeds: Sequence[int], *,
                        permutations: int = 100_000, resamples: int = 50_000,
                        seed: int = SEED) -> PrimaryClaim:
    """The claim's tests over the tasks every configuration named has complete (module doc)."""
    by_label = {group.label: group for group in groups}
    named = {label for pair in (*primary, *secondary) for label in pair}
    for label in named - set(by_label):
        raise ValueError(f"{label!r} is no configuration of the report; the configurations "
                         f"are: {'; '.join(map(repr, by_label))}.")
    values = {label: planned_ras(by_label[label], planned_seeds) for label in named}
    tasks = sorted(set.intersection(*(set(each) for each in values.values())))
    if not tasks:
        raise ValueError(f"no task has every planned seed ({', '.join(map(str, planned_seeds))}) "
                         f"finished for each of {', '.join(sorted(named))}: nothing to test.")

    def test(pair: tuple[str, str], is_primary: bool) -> PairTest:
        x = {task: values[pair[0]][task] for task in tasks}
        y = {task: values[pair[1]][task] for task in tasks}
        permuted = stratified_permutation_test(x, y, permutations=permutations, seed=seed)
        low, high = stratified_bootstrap_interval(x, y, resamples=resamples, seed=seed)
        paired = paired_sign_flip_test(x, y, permutations=permutations, seed=seed)
        return PairTest(pair[0], pair[1], is_primary, tuple(tasks), permuted.difference, low,
                        high, permuted.p_value, None, paired.p_value)

    tests = [test(pair, True) for pair in primary]
    adjusted = holm({f"{each.label} vs {each.baseline}": each.p_value for each in tests})
    tests = [replace(each, adjusted_p=adjusted[f"{each.label} vs {each.baseline}"])
             for each in tests]
    tests += [test(pair, False) for pair in secondary]
    _, after = planned_runs([by_label[label] for label in sorted(named)], planned_seeds)
    return PrimaryClaim(tuple(tests), tuple(planned_seeds), permutations, resamples, after)


PRIMARY_CLAIM_COLUMNS = ("configuration", "baseline", "hypothesis", "tasks", "difference",
                         "bootstrap_low", "bootstrap_high", "p_permutation", "p_holm",
                         "p_paired", "verdict")


def primary_claim_rows(claim: PrimaryClaim) -> Table:
    """One row per pair tested (:data:`PRIMARY_CLAIM_COLUMNS`)."""
    return Table(PRIMARY_CLAIM_COLUMNS, [
        {"configuration": each.label, "baseline": each.baseline,
         "hypothesis": "primary" if each.primary else "secondary",
         "tasks": " ".join(each.tasks), "difference": each.difference,
         "bootstrap_low": each.low, "bootstrap_high": each.high,
         "p_permutation": each.p_value, "p_holm": each.adjusted_p, "p_paired": each.paired_p,
         "verdict": each.verdict} for each in claim.tests])


def _p(header: str, name: str) -> Column:
    return Column(header, lambda row: EMPTY_CELL if row[name] is None else f"{row[name]:.4f}")


def primary_claim_markdown(claim: PrimaryClaim) -> str:
    """The section: one row per pair, then how it was tested."""
    table = primary_claim_rows(claim).markdown(columns=[
        Column("Pair", lambda row: f"{row['configuration']} − {row['baseline']}"),
        field_column("Hypothesis", "hypothesis"),
        Column("Tasks", lambda row: str(len(row["tasks"].split()))),
        Column("Δ mean RAS over tasks [95% bootstrap]",
               lambda row: f"{row['difference']:+.1f} [{row['bootstrap_low']:+.1f}, "
                           f"{row['bootstrap_high']:+.1f}]"),
        _p("p (stratified permutation)", "p_permutation"), _p("p (Holm)", "p_holm"),
        _p("p (paired, sensitivity)", "p_paired"), field_column("Verdict", "verdict")])
    seeds = ", ".join(map(str, claim.planned_seeds))
    tasks = ", ".join(claim.tests[0].tasks)
    text = [
        "## The primary claim (registered analysis plan)", "", table, "",
        f"Tasks: {tasks}; seeds {seeds} only. Δ: the mean over the tasks of the difference of "
        f"mean RAS, in points. The test shuffles each task's runs between the two labels, the "
        f"tasks independently ({claim.permutations:,} permutations; unpaired, as the plan "
        f"fixed); Holm's correction over the primary pairs at family α = {ALPHA:g}; the "
        f"interval resamples runs within each task and configuration ({claim.resamples:,} "
        f"times). The paired sign-flip test pairs runs by seed (a shared layout): reported, "
        f"not a verdict. *above* / *below*: Holm's p (a secondary pair: its own p) under "
        f"{ALPHA:g}; else *not resolved*."]
    if claim.after_looking:
        text += ["", "Runs of seeds outside the plan (added after looking), in no test here: "
                 + "; ".join(claim.after_looking) + "."]
    return "\n".join(text) + "\n"
