"""Comparisons with the thesis (its seed error counted) and the page shaped as a thesis table.

The intervals are checked against scipy's two-sample Welch interval on stand-in samples with
the thesis's mean, never against the code's own formula; the average's interval by its coverage
over simulated studies."""

import csv
import math

import numpy as np
import pytest
import report
from helpers import SEED0, SEED1, make_run
from scipy import stats

from temporal_torchrl.reports import group_runs
from temporal_torchrl.reports.aggregate import INCOMPLETE, VALUE, Cell, RunValue
from temporal_torchrl.reports.published import PublishedCell
from temporal_torchrl.reports.reliable import build_reliable_table
from temporal_torchrl.reports.statistics import ABOVE, BELOW, EQUIVALENT, NOT_RESOLVED
from temporal_torchrl.reports.tables import reliable_markdown
from temporal_torchrl.reports.thesis_comparison import compare_averages, compare_with_thesis
from temporal_torchrl.reports.thesis_table import NOT_RUN, build_thesis_table
from temporal_torchrl.runs import find_runs


def stand_in(mean: float, std: float, n: int = 4) -> np.ndarray:
    """n values with exactly this mean and sample std."""
    signs = np.array([(-1.0) ** index for index in range(n)])
    signs -= signs.mean()
    return mean + signs * std / signs.std(ddof=1)


@pytest.mark.parametrize("ours, thesis_mean, thesis_std", [
    ([48.0, 32.0, 42.0, 44.7], 53.5, None),        # a thesis without a std: ours assumed
    ([74.0, 73.3, 82.0, 74.7], 78.5, None),
    ([151.0, 161.0, 120.0, 300.0, 90.0, 88.0], 271.0, 29.0),  # Table 5.2 prints its std
])
def test_interval_is_welchs_with_the_thesis_as_four_seeds(ours, thesis_mean, thesis_std):
    comparison = compare_with_thesis(ours, thesis_mean, thesis_std)
    theirs = stand_in(thesis_mean, np.std(ours, ddof=1) if thesis_std is None else thesis_std)
    result = stats.ttest_ind(ours, theirs, equal_var=False)
    low, high = result.confidence_interval(0.95)
    assert comparison.difference == pytest.approx(np.mean(ours) - thesis_mean)
    assert (comparison.low, comparison.high) == (pytest.approx(low), pytest.approx(high))
    assert comparison.degrees_of_freedom == pytest.approx(result.df)
    assert comparison.std_assumed == (thesis_std is None)
    # Bonferroni over 9 cells is scipy's interval at level 1 - 0.05 / 9
    wide = compare_with_thesis(ours, thesis_mean, thesis_std, cells=9)
    low9, high9 = result.confidence_interval(1 - 0.05 / 9)
    assert (wide.adjusted_low, wide.adjusted_high) == (pytest.approx(low9), pytest.approx(high9))


def test_readings_by_the_analysis_plan():
    # drawer-open SAC on 4 seeds: the 95% interval includes 0, the 90% one leaves ±10: that is
    # not agreement, it is not resolved
    drawer = compare_with_thesis([48.0, 32.0, 42.0, 44.7], 53.5, margin=10.0)
    assert drawer.verdict == NOT_RESOLVED and drawer.low < 0 < drawer.high
    assert drawer.describe().endswith(": not resolved")
    # window-close FuRL + D3: the 90% interval (scipy's, on stand-in thesis seeds) inside ±10
    ours = [74.0, 73.3, 82.0, 74.7]
    quiet = compare_with_thesis(ours, 78.5, margin=10.0)
    low90, high90 = stats.ttest_ind(ours, stand_in(78.5, np.std(ours, ddof=1)),
                                    equal_var=False).confidence_interval(0.90)
    assert (quiet.equivalence_low, quiet.equivalence_high) == (pytest.approx(low90),
                                                               pytest.approx(high90))
    assert -10 < low90 and high90 < 10 and quiet.verdict == EQUIVALENT
    assert "equivalent within ±10 (90% [" in quiet.describe()
    assert compare_with_thesis(ours, 78.5).verdict == NOT_RESOLVED  # no margin: never equivalent
    close = compare_with_thesis([57.0, 59.0, 55.0, 58.0], 53.5, cells=9, margin=10.0)
    assert close.low > 0 and close.adjusted_low < 0 and close.verdict == EQUIVALENT  # +3.8
    apart = compare_with_thesis([60.0, 70.0, 65.0, 75.0], 53.5, cells=9, margin=10.0)
    assert apart.low > 0 and apart.adjusted_low < 0 and apart.verdict == NOT_RESOLVED
    assert "not resolved (above at 95%, not over 9 cells [" in apart.describe()
    far = compare_with_thesis([90.0, 91.0, 89.0, 90.5], 53.5, cells=9, margin=10.0)
    assert far.verdict == ABOVE and far.adjusted_low > 0
    assert far.describe().endswith("]") and "above over 9 cells" in far.describe()
    near = compare_with_thesis([47.0, 47.5, 46.5, 47.2], 53.5, cells=9, margin=10.0)
    assert near.verdict == BELOW and near.describe().endswith(", by less than 10")


def test_an_interval_needs_a_seed_error():
    with pytest.raises(ValueError, match="at least 2 seeds"):
        compare_with_thesis([50.0], 53.5)
    with pytest.raises(ValueError, match="no seed error"):
        compare_with_thesis([50.0, 50.0], 53.5)


def test_a_cell_is_compared_when_one_side_has_a_seed_error():
    """One rule for the report's comparisons and the thesis-table page: a complete cell of 2 or
    more values, with our spread or a printed std."""
    def cell(*values: float) -> Cell:
        runs = tuple(RunValue(None, value, VALUE) for value in values)
        std = float(np.std(values, ddof=1)) if len(values) > 1 else None
        return Cell(runs, float(np.mean(values)), std)

    printed, unprinted = PublishedCell(53.5, 9.0), PublishedCell(53.5)
    assert cell(48.0, 32.0).comparable_with(unprinted)
    assert cell(50.0, 50.0).comparable_with(printed)  # compare_with_thesis accepts it
    compare_with_thesis([50.0, 50.0], printed.mean, printed.std)
    assert not cell(50.0, 50.0).comparable_with(unprinted)  # no seed error on either side
    assert not cell(50.0).comparable_with(printed)
    pending = Cell((RunValue(None, 50.0, VALUE), RunValue(None, None, INCOMPLETE),
                    RunValue(None, 40.0, VALUE)), 45.0, 7.1)
    assert not pending.comparable_with(printed)


def test_average_over_one_task_is_the_cells_comparison():
    ours = [48.0, 32.0, 42.0, 44.7]
    single, average = compare_with_thesis(ours, 53.5), compare_averages([(ours, 53.5, None)])
    assert (average.low, average.high) == (pytest.approx(single.low), pytest.approx(single.high))


def test_average_interval_covers_the_true_difference_95_percent_of_the_time():
    # Three tasks with different spreads, 4 seeds each side, no true difference: the interval
    # of the average difference must contain 0 in about 95% of simulated studies.
    rng = np.random.default_rng(0)
    spreads, trials, covered = (5.0, 12.0, 20.0), 3000, 0
    for _ in range(trials):
        cells = [(rng.normal(50.0, spread, 4), float(rng.normal(50.0, spread, 4).mean()),
                  spread) for spread in spreads]
        comparison = compare_averages(cells)
        covered += comparison.low <= 0.0 <= comparison.high
    assert abs(covered / trials - 0.95) < 0.015


# --------------------------------------------------------------------------- the page
SAC, FURL1, BEST = (("preset=sac", "protocol=stage2"), ("preset=furl_rho1", "protocol=stage2"),
                    ("preset=none", "protocol=stage2"))


def _study(root, task, configuration, successes_by_seed):
    for seed, successes in enumerate(successes_by_seed):
        make_run(root, f"{task}/{configuration[0]}/s{seed}", successes, *configuration,
                 f"env.task={task}", f"env.seed={seed}", "encoder.name=metaworld_small",
                 finished=True)


def ras_successes(rate_percent_of_150: int, budget: int = 300) -> list[bool]:
    """``budget`` episodes whose last 150 hold ``rate_percent_of_150`` successes."""
    return [False] * (budget - 150) + [True] * rate_percent_of_150 + [False] * (
        150 - rate_percent_of_150)


def test_thesis_table_page_lays_out_ours_beside_the_thesis(tmp_path):
    _study(tmp_path, "drawer-open", SAC, [ras_successes(60), ras_successes(75),
                                          ras_successes(90)])
    _study(tmp_path, "drawer-open", BEST, [ras_successes(135), ras_successes(140)])
    _study(tmp_path, "window-close", SAC, [ras_successes(45, 200), ras_successes(55, 200)])
    page = build_thesis_table(group_runs(find_runs([tmp_path])), "5.12")
    keys = [column.key for column in page.columns]
    assert keys[0] == "SAC" and keys[1] == "FuRL ρ=1.0"  # not run: the thesis's label
    best = next(key for key in keys if key.startswith("FuRL + r_D3 ρ=1.0"))
    assert page.cells["drawer-open", "SAC"].mean == pytest.approx(50.0)
    assert ("door-open", "SAC") not in page.cells
    # SAC on two tasks: our average of task means beside the thesis's over the same tasks
    average = page.averages["SAC"]
    assert average.tasks == ("drawer-open", "window-close")
    assert average.ours == pytest.approx((50.0 + 100 / 3) / 2)
    assert average.thesis == pytest.approx((53.5 + 32.8) / 2)
    assert average.comparison is not None and page.averages[best].comparison is None
    # three cells compared (SAC twice, FuRL + D3 once): each interval is table-wide over 3
    assert {comparison.comparisons for comparison in page.comparisons.values()} == {3}
    sac = page.comparisons["drawer-open", "SAC"]
    scipy_low, _ = stats.ttest_ind([40.0, 50.0, 60.0], stand_in(53.5, 10.0),
                                   equal_var=False).confidence_interval(1 - 0.05 / 3)
    assert sac.adjusted_low == pytest.approx(scipy_low)


def test_report_leads_with_the_thesis_table_and_compares_the_pairs_asked_for(tmp_path):
    runs = tmp_path / "runs"
    _study(runs, "drawer-open", SAC, [ras_successes(60), ras_successes(75)])
    _study(runs, "drawer-open", FURL1, [ras_successes(80), ras_successes(95)])
    _study(runs, "drawer-open", BEST, [ras_successes(135), ras_successes(140)])
    out = tmp_path / "out"
    report.main([str(runs), "--out", str(out), "--thesis-table", "5.12", "--bootstrap", "200",
                 "--compare", "FuRL ρ=1 + D3 λ=4 (b_g)", "FuRL ρ=1",
                 "--compare", "FuRL ρ=1", "SAC"])
    page = (out / "table_5_12.md").read_text()
    row = next(line for line in page.splitlines() if line.startswith("| door-open |"))
    assert row.count(NOT_RUN) == 6
    report_md = (out / "report.md").read_text()
    assert report_md.index("## Thesis Table 5.12") < report_md.index("## How to read")
    aggregates = (out / "aggregates.md").read_text()
    assert "| P(FuRL ρ=1 + D3 λ=4 (b_g) > FuRL ρ=1) | drawer-open | 1.00 [1.00, 1.00] |" \
        in aggregates
    assert ("every run of FuRL ρ=1 + D3 λ=4 (b_g) scored above every run of FuRL ρ=1 on each "
            "of the 1 task(s) in common (2 of FuRL ρ=1 + D3 λ=4 (b_g) and 2 of FuRL ρ=1 runs)"
            ) in aggregates and "not certainty" in aggregates
    with (out / "table_5_12.csv").open() as file:
        rows = {(row["task"], row["column"]): row for row in csv.DictReader(file)}
    assert rows["drawer-open", "SAC"]["reading"] in (ABOVE, BELOW, EQUIVALENT, NOT_RESOLVED)
    assert rows["push", "SAC"]["our_configuration"] == NOT_RUN
    assert math.isclose(float(rows["drawer-open", "SAC"]["thesis_mean"]), 53.5)


def test_bad_thesis_table_and_compare_labels_are_named(tmp_path):
    make_run(tmp_path, "s0", SEED0, "preset=sac", "protocol=stage2", "env.seed=0")
    make_run(tmp_path, "s1", SEED1, "preset=sac", "protocol=stage2", "env.seed=1")
    with pytest.raises(SystemExit, match=r"--thesis-table 9.9: no thesis table '9.9'; the "
                                         r"transcribed ones are 5.2, 5.3"):
        report.main([str(tmp_path), "--out", str(tmp_path / "o"), "--thesis-table", "9.9"])
    with pytest.raises(SystemExit, match="--compare 'FuRL': no configuration has that label"):
        report.main([str(tmp_path), "--out", str(tmp_path / "o"), "--compare", "FuRL", "SAC"])
    with pytest.raises(ValueError, match="'FuRL' is no configuration of the report"):
        build_reliable_table(group_runs(find_runs([tmp_path])), "ras", pairs=[("FuRL", "SAC")])
    assert "probabilities of improvement asked for" not in reliable_markdown(
        build_reliable_table(group_runs(find_runs([tmp_path])), "ras", reps=50))
