"""The registered plan's primary claim from runs: the tasks each configuration has complete on
the planned seeds, Δ, Holm over the primary pairs, the seeds added after looking left out, and
each run's commits; the p-values against a relabelling enumerated here."""

import csv
import hashlib
import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import report
from helpers import make_run

from temporal_torchrl.reports import group_runs
from temporal_torchrl.reports.primary_claim import build_primary_claim
from temporal_torchrl.reports.thesis_table import build_thesis_table
from temporal_torchrl.runs import find_runs

SAC, FURL, BEST = (("preset=sac", "protocol=stage2"), ("preset=furl_rho1", "protocol=stage2"),
                   ("preset=none", "protocol=stage2"))
LABELS = {SAC: "SAC", FURL: "FuRL ρ=1", BEST: "FuRL ρ=1 + D3 λ=4 (b_g)"}


def ras_run(root, task, configuration, seed, successes_of_150, commit=None):
    """A finished window-close (budget 200) or drawer-open (300) run whose RAS is
    ``successes_of_150`` / 150."""
    budget = {"window-close": 200, "drawer-open": 300}[task]
    successes = [False] * (budget - 150) + [True] * successes_of_150 + [False] * (
        150 - successes_of_150)
    run = make_run(root, f"{task}/{configuration[0]}/seed{seed}", successes, *configuration,
                   f"env.task={task}", f"env.seed={seed}", "encoder.name=metaworld_small",
                   finished=True)
    if commit is not None:
        summary = {"episodes": budget, "provenance": [{"episode": 0, "commit": commit,
                                                        "clean": True}]}
        (run / "summary.json").write_text(json.dumps(summary))


RAS = {  # successes of 150, per task, configuration and seed 0, 1
    "window-close": {SAC: (45, 60), FURL: (60, 75), BEST: (110, 120)},
    "drawer-open": {SAC: (60, 90), FURL: (55, 70), BEST: (135, 140)},
}


@pytest.fixture
def runs(tmp_path):
    for task, columns in RAS.items():
        for configuration, values in columns.items():
            for seed, value in enumerate(values):
                ras_run(tmp_path, task, configuration, seed, value, commit="ab" * 20)
    ras_run(tmp_path, "drawer-open", SAC, 4, 10)  # added after looking: in no test
    ras_run(tmp_path, "window-close", SAC, 2, 10)  # not planned either
    return tmp_path


def exact_p(x: dict, y: dict) -> float:
    """Every relabelling of each task's pooled runs, enumerated here."""
    observed = np.mean([np.mean(x[task]) - np.mean(y[task]) for task in x])
    per_task = []
    for task in x:
        pooled = x[task] + y[task]
        per_task.append([np.mean([pooled[i] for i in chosen])
                         - np.mean([pooled[i] for i in range(len(pooled)) if i not in chosen])
                         for chosen in itertools.combinations(range(len(pooled)), len(x[task]))])
    differences = [np.mean(choice) for choice in itertools.product(*per_task)]
    return np.mean([abs(d) >= abs(observed) - 1e-9 for d in differences])


def test_the_claim_is_tested_on_the_planned_seeds_with_holm_over_the_primary_pairs(runs):
    groups = group_runs(find_runs([runs]))
    claim = build_primary_claim(
        groups, [(LABELS[BEST], LABELS[FURL]), (LABELS[BEST], LABELS[SAC])],
        [(LABELS[FURL], LABELS[SAC])], planned_seeds=[0, 1], permutations=100_000,
        resamples=2_000)
    ras = {label: {task: [100 * value / 150 for value in RAS[task][configuration]]
                   for task in RAS} for configuration, label in LABELS.items()}
    best_furl, best_sac, furl_sac = claim.tests
    assert best_furl.tasks == ("drawer-open", "window-close")
    expected = np.mean([np.mean(ras[LABELS[BEST]][task]) - np.mean(ras[LABELS[FURL]][task])
                        for task in RAS])
    assert best_furl.difference == pytest.approx(expected)
    for test, (x, y) in zip(claim.tests, [(BEST, FURL), (BEST, SAC), (FURL, SAC)], strict=True):
        assert test.p_value == pytest.approx(exact_p(ras[LABELS[x]], ras[LABELS[y]]), abs=0.005)
    # Holm by hand over the two primary pairs: the smaller p times 2, the larger times 1, kept
    # monotone; the secondary pair is outside the family
    low, high = sorted([best_furl.p_value, best_sac.p_value])
    adjusted = {low: min(1.0, 2 * low), high: max(min(1.0, 2 * low), high)}
    assert best_furl.adjusted_p == pytest.approx(adjusted[best_furl.p_value])
    assert best_sac.adjusted_p == pytest.approx(adjusted[best_sac.p_value])
    assert furl_sac.adjusted_p is None and not furl_sac.primary
    # with 2 runs against 2 on 2 tasks the smallest possible p is 2/36: not resolved
    assert best_furl.p_value >= 2 / 36 - 0.01 and best_furl.verdict == "not resolved"
    assert claim.after_looking == ("SAC, drawer-open, seed 4", "SAC, window-close, seed 2")


def test_report_writes_the_claim_and_each_cells_commits(runs, tmp_path):
    out = tmp_path / "out"
    unrecorded = runs / "window-close" / BEST[0] / "seed1" / "summary.json"
    unrecorded.write_text(json.dumps({"episodes": 200}))  # ran before the provenance record
    report.main([str(runs), "--out", str(out), "--thesis-table", "5.12", "--bootstrap", "100",
                 "--primary", LABELS[BEST], LABELS[FURL], "--primary", LABELS[BEST], LABELS[SAC],
                 "--secondary", LABELS[FURL], LABELS[SAC], "--planned-seeds", "0", "1"])
    claim = (out / "primary_claim.md").read_text()
    assert "| FuRL ρ=1 + D3 λ=4 (b_g) − FuRL ρ=1 | primary | 2 |" in claim
    assert "added after looking" in claim and "SAC, drawer-open, seed 4" in claim
    with (out / "primary_claim.csv").open() as file:
        assert [row["hypothesis"] for row in csv.DictReader(file)] == [
            "primary", "primary", "secondary"]
    page = (out / "table_5_12.md").read_text()
    # the page holds the planned seeds only: drawer-open's SAC on 2 seeds, seed 4 named apart
    assert "| drawer-open | 50.0 ± 14.1 (n=2) · thesis 53.5 |" in page
    assert "as seeds added after looking" in page and "SAC, drawer-open, seed 4" in page
    assert f"| SAC | drawer-open | {'ab' * 6} |" in page
    assert (f"| FuRL + r_D3 ρ=1.0 (ours: FuRL ρ=1 + D3 λ=4 (b_g)) | window-close | {'ab' * 6}; "
            f"not recorded (1 run) |") in page
    with (out / "runs.csv").open() as file:
        commits = {(row["configuration"], row["task"], row["seed"]): row["commits"]
                   for row in csv.DictReader(file)}
    assert commits["SAC", "drawer-open", "0"] == "ab" * 6
    assert commits["SAC", "drawer-open", "4"] == "not recorded"


def test_a_claim_without_a_complete_task_is_named(runs):
    groups = group_runs(find_runs([runs]))
    with pytest.raises(ValueError, match=r"no task has every planned seed \(0, 1, 2\)"):
        build_primary_claim(groups, [(LABELS[BEST], LABELS[FURL])], [], planned_seeds=[0, 1, 2])


#: The SHA-256 of the Table 5.12 analysis plan as registered in commit 0154dd6, before its runs.
REGISTERED_PLAN = "c0aebeb5b2ca94095ced7ce33c15d3c773bc450d45393d80f79f1e2b535fc170"


def test_the_registered_analysis_plan_is_unedited():
    """The plan fixes the analysis before the runs: an edit after them would let the data choose
    it. Amendments go in a file of their own, dated, beside it."""
    plan = Path(__file__).resolve().parents[1] / "docs/results/table_5_12/analysis_plan.md"
    assert hashlib.sha256(plan.read_bytes()).hexdigest() == REGISTERED_PLAN


def test_planned_seeds_keep_the_aggregates_and_comparisons_to_them(runs, tmp_path):
    out = tmp_path / "out"
    report.main([str(runs), "--out", str(out), "--bootstrap", "100",
                 "--compare", LABELS[BEST], LABELS[SAC], "--planned-seeds", "0", "1"])
    with (out / "aggregates.csv").open() as file:
        scored = {row["configuration"]: row["runs_scored"] for row in csv.DictReader(file)
                  if row["metric"] == "ras"}
    assert scored[LABELS[SAC]] == "4"  # seeds 0 and 1 on two tasks; seeds 2 and 4 left out
    with (out / "ras.csv").open() as file:
        sac = {row["task"]: row["n"] for row in csv.DictReader(file)
               if row["configuration"] == LABELS[SAC] and row["task"] != "Average"}
    assert sac == {"drawer-open": "3", "window-close": "3"}  # the per-metric table keeps all


def test_a_cell_short_of_its_planned_seeds_is_shown_not_judged(runs):
    groups = group_runs(find_runs([runs]))
    page = build_thesis_table(groups, "5.12", planned_seeds=[0, 1, 2])
    assert ("drawer-open", "SAC") in page.cells  # seeds 0 and 1 of 0-2: shown
    assert list(page.comparisons) == [("window-close", "SAC")]  # the one cell with seed 2 too
    assert build_thesis_table(groups, "5.12", planned_seeds=[0, 1]).comparisons
