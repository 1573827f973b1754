"""The report's evaluation section (recipes/report.py over runs with eval.csv): the figure, the
final evaluation success table checked against a computation of its own, and nothing at all for
runs that did not evaluate."""

import csv

import numpy as np
import pytest
import report
from helpers import SEED0, SEED1, make_run

from temporal_torchrl.runs import find_runs

FURL = ("preset=furl", "protocol=stage2")
RHO1 = (*FURL, "reward.rho=1.0")
HEADER = ["episode", "env_steps", "episodes", "success_rate", "final_success_rate", "return",
          "episode_length"]
# (configuration, task, seed) -> success rates of the evaluations after episodes 100, 200, 300;
# the last one is the run's final evaluation success.
RATES = {
    ("FuRL ρ=0.05", "drawer-open", 0): (0.0, 0.2, 0.6),
    ("FuRL ρ=0.05", "drawer-open", 1): (0.1, 0.3, 0.9),
    ("FuRL ρ=0.05", "window-close", 0): (0.2, 0.5, 0.4),
    ("FuRL ρ=0.05", "window-close", 1): (0.0, 0.4, 1.0),
    ("FuRL ρ=1", "drawer-open", 0): (0.0, 0.0, 0.1),
    ("FuRL ρ=1", "drawer-open", 1): (0.0, 0.1, 0.3),
    ("FuRL ρ=1", "window-close", 0): (0.1, 0.2, 0.2),
    ("FuRL ρ=1", "window-close", 1): (0.0, 0.0, 0.7),
}
OVERRIDES = {"FuRL ρ=0.05": FURL, "FuRL ρ=1": RHO1}
BOOTSTRAP = 200


def write_evaluations(run_dir, rates, seed):
    """eval.csv as the recipe writes it: 10 evaluation episodes after every 100 training
    episodes (env steps differ a little between seeds)."""
    with (run_dir / "eval.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(HEADER)
        for number, rate in enumerate(rates, start=1):
            writer.writerow([100 * number, 50_000 * number + 17 * seed, 10, rate, rate / 2,
                             -400 + 100 * rate, 500])


def make_runs(root, evaluated=True, unevaluated=()):
    """The runs of RATES (with eval.csv when ``evaluated``), and seed-0/1 runs without one of
    each configuration in ``unevaluated`` (its label: its overrides)."""
    for (label, task, seed), rates in RATES.items():
        run_dir = make_run(root, f"{label}-{task}-{seed}", SEED0 if seed == 0 else SEED1,
                           *OVERRIDES[label], f"env.task={task}", f"env.seed={seed}",
                           finished=True)
        if evaluated:
            write_evaluations(run_dir, rates, seed)
    for label, overrides in dict(unevaluated).items():
        for seed, successes in enumerate((SEED0, SEED1)):
            make_run(root, f"{label}-{seed}", successes, *overrides, f"env.seed={seed}",
                     finished=True)


def read_csv(path):
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def finals(label, task=None):
    return np.array([rates[-1] for (each, other, _), rates in RATES.items()
                     if each == label and task in (None, other)])


def test_the_reader_gives_a_runs_evaluations(tmp_path):
    make_runs(tmp_path)
    make_run(tmp_path, "none", SEED0, *FURL, "env.seed=5")
    runs = {run.path.name: run for run in find_runs([tmp_path])}
    rows = runs["FuRL ρ=1-window-close-1"].evaluations
    assert [row["success_rate"] for row in rows] == [0.0, 0.0, 0.7]
    assert [(row["episode"], row["env_steps"]) for row in rows] == [
        (100, 50_017), (200, 100_017), (300, 150_017)]
    assert runs["none"].evaluations == ()


def test_report_tabulates_and_plots_the_final_evaluation_success(tmp_path):
    make_runs(tmp_path / "runs", unevaluated={"SAC": ("preset=sac", "protocol=stage2")})
    out = tmp_path / "out"
    report.main([str(tmp_path / "runs"), "--out", str(out), "--bootstrap", str(BOOTSTRAP)])

    figure = out / "evaluation_curves.png"
    assert figure.is_file() and figure.stat().st_size > 10_000
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "report.md").read_text()
    assert "](evaluation_curves.png)" in page
    assert "## Evaluation of the deterministic policy" in page
    assert (out / "evaluation.md").read_text() in page
    assert "8 of 10 runs evaluated" in page

    rows = read_csv(out / "evaluation.csv")
    cells = {(row["configuration"], row["task"]): row for row in rows}
    # The unevaluated configuration has no row; every evaluated cell and configuration has one.
    assert {label for label, _ in cells} == {"FuRL ρ=0.05", "FuRL ρ=1"}
    ras_drawer = (100.0 + 70 / 150 * 100) / 2  # SEED0 and SEED1 over episodes 151-300
    for label in ("FuRL ρ=0.05", "FuRL ρ=1"):
        for task in ("drawer-open", "window-close"):
            row, values = cells[label, task], finals(label, task)
            assert float(row["last_success_rate_mean"]) == pytest.approx(np.mean(values))
            assert float(row["last_success_rate_std"]) == pytest.approx(np.std(values, ddof=1))
            assert (row["evaluated"], row["last_evaluation_episodes"]) == ("2", "300")
        assert float(cells[label, "drawer-open"]["ras_mean"]) == pytest.approx(ras_drawer,
                                                                                rel=1e-6)
        # Over tasks and seeds: IQM of the 4 pooled finals = mean of the middle two (25% cut
        # at each end); Mean = mean of the two task means.
        pooled = np.sort(finals(label))
        iqm = pooled[1:3].mean()
        mean = np.mean([finals(label, task).mean() for task in ("drawer-open", "window-close")])
        overall = cells[label, "all"]
        assert float(overall["iqm"]) == pytest.approx(iqm)
        assert float(overall["mean"]) == pytest.approx(mean)
        assert float(overall["iqm_ci95_low"]) <= iqm <= float(overall["iqm_ci95_high"])
        assert float(overall["mean_ci95_low"]) <= mean <= float(overall["mean_ci95_high"])
        assert pooled[0] <= float(overall["iqm_ci95_low"])
        assert float(overall["iqm_ci95_high"]) <= pooled[-1]
        # RAS's rliable IQM beside it, the one of aggregates.csv.
        ras = next(row for row in read_csv(out / "aggregates.csv")
                   if (row["metric"], row["configuration"]) == ("ras", label))
        assert overall["ras_iqm"] == ras["iqm"] != ""

    # The Markdown shows the same numbers, in %: 0.6 and 0.9 -> 75.0 ± 21.2 (n=2).
    line = next(line for line in page.splitlines()
                if line.startswith("| drawer-open | FuRL ρ=0.05 |"))
    assert f"{100 * finals('FuRL ρ=0.05', 'drawer-open').mean():.1f} ± " \
           f"{100 * finals('FuRL ρ=0.05', 'drawer-open').std(ddof=1):.1f} (n=2)" in line
    assert f"{ras_drawer:.1f} ± 37.7 (n=2)" in line  # the RAS table's cell beside it


def test_runs_without_evaluations_get_no_evaluation_section(tmp_path):
    make_runs(tmp_path / "runs", evaluated=False)
    out = tmp_path / "out"
    report.main([str(tmp_path / "runs"), "--out", str(out), "--bootstrap", "20"])
    written = {path.name for path in out.iterdir()}
    assert "report.md" in written
    assert not {name for name in written if "evaluation" in name}
    assert "evaluation" not in (out / "report.md").read_text().lower()
