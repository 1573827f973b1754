"""The report's row model (temporal_torchrl.reports.rows): one set of rows, two renderings."""

import csv
import doctest
import io

import pytest

from temporal_torchrl.reports import rows as rows_module
from temporal_torchrl.reports.rows import EMPTY_CELL, Column, Table, csv_text, field_column


def test_docstring_example_runs():
    assert doctest.testmod(rows_module).failed == 0


def test_csv_text_of_each_type():
    assert [csv_text(value) for value in (None, True, False, 4, 0.1 + 0.2, 1 / 3, "a b")] == [
        "", "true", "false", "4", "0.3", "0.3333333333", "a b"]


def test_markdown_and_csv_read_the_same_rows():
    table = Table(("task", "configuration", "mean", "best"),
                  [{"task": "push", "configuration": "SAC", "mean": 28.0, "best": False},
                   {"task": "push", "configuration": "FuRL", "mean": 56.5, "best": True},
                   {"task": "reach", "configuration": "SAC", "mean": 90.25}])

    def text(row):
        return f"**{row['mean']:.1f}**" if row.get("best") else f"{row['mean']:.1f}"

    assert table.pivot_markdown("task", "configuration", text, header="Task").splitlines() == [
        "| Task | SAC | FuRL |", "|---|---|---|",
        "| push | 28.0 | **56.5** |", f"| reach | 90.2 | {EMPTY_CELL} |"]
    wide = table.pivot_markdown(lambda row: row["task"].upper(), "configuration", text,
                                header="Task", lines=["PUSH", "PICK"], missing="not run")
    assert wide.splitlines()[-1] == "| PICK | not run | not run |"
    long = table.markdown(lambda row: row["configuration"] == "SAC",
                          [field_column("Task", "task"), field_column("Best", "best")])
    assert long.splitlines()[2:] == ["| push | false |", f"| reach | {EMPTY_CELL} |"]
    written = io.StringIO()
    writer = csv.DictWriter(written, table.fields)
    writer.writeheader()
    writer.writerows(table.csv_rows())
    assert list(csv.DictReader(io.StringIO(written.getvalue())))[2] == {
        "task": "reach", "configuration": "SAC", "mean": "90.25", "best": ""}


def test_a_row_with_an_undeclared_field_is_refused():
    with pytest.raises(ValueError, match=r"fields \['meam'\] the table does not declare"):
        Table(("task", "mean"), [{"task": "push", "meam": 1.0}], (Column("Task", str),))
