"""The Table 5.12 page's hand-written tables against the report it summarises: each number the
page leads with must be the committed ``table_5_12.csv``'s, and every judged cell must be
there, so a cell that finishes cannot be left out of the page (push's SAC once was)."""

import csv
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[1] / "docs" / "results" / "table_5_12"
#: The page's column names -> the report's (the thesis's column names).
COLUMNS = {"SAC": "SAC", "FuRL ρ=1": "FuRL ρ=1.0", "FuRL ρ=1 + D3 λ=4": "FuRL + r_D3 ρ=1.0"}
PLANNED_SEEDS = 4
THESIS_AVERAGE = "the thesis's average"


def page_tables() -> list[list[list[str]]]:
    """The Markdown tables of the page, each a list of rows of stripped cells (header and
    separator dropped)."""
    tables, current = [], []
    for line in (PAGE / "README.md").read_text().splitlines():
        if line.startswith("|"):
            current.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif current:
            tables.append(current[2:])
            current = []
    if current:
        tables.append(current[2:])
    return tables


def report_rows() -> dict[tuple[str, str], dict[str, str]]:
    with (PAGE / "table_5_12.csv").open() as file:
        return {(row["task"], row["column"]): row for row in csv.DictReader(file)
                if row["column"] in COLUMNS.values()}


def signed(text: str) -> str:
    """A number as the page prints it: one decimal, a sign, the minus sign U+2212."""
    return f"{float(text):+.1f}".replace("-", "−")


def test_the_leading_table_is_the_reports():
    rows = report_rows()
    leading = page_tables()[0]
    tasks = [task for task, column in rows if column == "SAC" and task in {
        "drawer-open", "door-open", "window-open", "window-close", "push",
        "button-press-topdown"}]
    assert [row[0] for row in leading[:len(tasks)]] == tasks
    for task, *cells in leading[:len(tasks)]:
        for cell, column in zip(cells, COLUMNS.values(), strict=True):
            row = rows[task, column]
            thesis = f"{float(row['thesis_mean']):.1f}"
            if not row["n"]:
                assert cell == f"not run · {thesis}", (task, column)
                continue
            ours = f"{float(row['mean']):.1f} ± {float(row['std']):.1f}"
            if int(row["n"]) < PLANNED_SEEDS:
                ours += f" ({row['n']} of {PLANNED_SEEDS} seeds)"
            assert cell == f"{ours} · {thesis}", (task, column)
    averages = {column: row for (task, column), row in rows.items()
                if task.startswith("average of ")}
    [label, *cells] = leading[len(tasks)]
    assert label == "average over the tasks run"
    for cell, column in zip(cells, COLUMNS.values(), strict=True):
        row = averages[column]
        count = len(row["task"].removeprefix("average of ").split())
        assert cell == (f"{float(row['mean']):.1f} ({count} tasks) · "
                        f"{float(row['thesis_mean']):.1f}"), column
    [label, *cells] = leading[len(tasks) + 1]
    assert label == "the thesis's average (its six tasks)"
    thesis = [rows[THESIS_AVERAGE, column]["thesis_mean"] for column in COLUMNS.values()]
    assert cells == [f"{float(mean):.1f}" for mean in thesis]


def test_each_judged_cell_has_its_verdict_on_the_page():
    rows = report_rows()
    verdicts = next(table for table in page_tables() if table[0][0].startswith("SAC, "))
    judged = {(task, column) for (task, column), row in rows.items() if row["reading"]}
    shown = set()
    for name, difference, verdict in verdicts:
        page_column, task = name.split(", ", 1)
        column = COLUMNS[page_column]
        if task.startswith("average"):
            [task] = [key for key, each in rows if each == column and key.startswith("average")]
        row = rows[task, column]
        shown.add((task, column))
        assert difference == (f"{signed(row['difference'])} [{signed(row['difference_ci95_low'])}"
                              f", {signed(row['difference_ci95_high'])}]"), name
        reading = row["reading"]
        word = {"equivalent": "equivalent within ±10"}.get(reading, reading)
        assert verdict.startswith(word), (name, verdict, reading)
        if reading in ("above", "below"):
            assert (f"[{signed(row['difference_adjusted_low'])}, "
                    f"{signed(row['difference_adjusted_high'])}]") in verdict, name
    assert shown == judged


@pytest.mark.parametrize("page", ["README.md", "../../results.md",
                                  "../sac_column/README.md",
                                  "../window_close_cpu_study/README.md"])
def test_no_reading_calls_an_interval_through_zero_agreement(page):
    """The plan's vocabulary: 'agrees' is not a verdict (an interval that includes zero is not
    resolved); the pages may say what they once said, in quotes."""
    text = (PAGE / page).read_text()
    for word in ("agrees with the thesis", "agree with the thesis", "every cell agrees",
                 "both agree"):
        assert word not in text.replace(f'"{word}', ""), (page, word)
