"""One row model for the report's tables, written to CSV and to Markdown by one renderer.

A :class:`Table` is a list of rows, each a mapping of CSV field to a typed value (``str``,
``int``, ``float``, ``bool`` or None), and two views of them: the CSV, every field of every row,
and the Markdown, a choice of columns, each a header and a function of the row alone. Since a
Markdown cell is written from its row's fields and nothing else, the two renderings cannot
disagree: a number the Markdown prints is in the CSV, to 10 significant digits.

The Markdown view is either one line per row (:meth:`Table.markdown`) or, for the thesis's
layout, a pivot: one line per value of one field (the task), one column per value of another
(the configuration), each cell a function of the row there (:meth:`Table.pivot_markdown`).

Example:
    >>> from temporal_torchrl.reports.rows import Column, Table
    >>> table = Table(("task", "mean", "n"), [{"task": "push", "mean": 41.75, "n": 4}],
    ...               (Column("Task", lambda row: row["task"]),
    ...                Column("RAS", lambda row: f"{row['mean']:.1f} (n={row['n']})")))
    >>> table.csv_rows()
    [{'task': 'push', 'mean': '41.75', 'n': '4'}]
    >>> print(table.markdown())
    | Task | RAS |
    |---|---|
    | push | 41.8 (n=4) |
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

#: A field's value: what the CSV writes, and what the Markdown reads.
Value = str | int | float | bool | None
Row = Mapping[str, Value]
#: An empty Markdown cell.
EMPTY_CELL = "—"


def csv_text(value: Value) -> str:
    """How the CSV writes a value: None empty, a bool ``true``/``false``, a float to 10
    significant digits."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.10g}"
    return str(value)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


@dataclass(frozen=True)
class Column:
    """A Markdown column: its header and its cell, a function of the row."""

    header: str
    text: Callable[[Row], str]


def field_column(header: str, name: str) -> Column:
    """A Markdown column that prints one field as the CSV does (empty as —)."""
    return Column(header, lambda row: csv_text(row.get(name)) or EMPTY_CELL)


@dataclass(frozen=True)
class Table:
    """Rows of typed fields (module doc).

    Attributes:
        fields: the CSV's columns, in order; a row may leave a field out (written empty) but
            holds no other.
        rows: the rows, in order.
        columns: the Markdown's columns of :meth:`markdown`.
    """

    fields: tuple[str, ...]
    rows: Sequence[Row]
    columns: tuple[Column, ...] = field(default=())

    def __post_init__(self) -> None:
        for row in self.rows:
            unknown = set(row) - set(self.fields)
            if unknown:
                raise ValueError(f"a row has fields {sorted(unknown)} the table does not "
                                 f"declare; its fields are {list(self.fields)}.")

    def csv_rows(self) -> list[dict[str, str]]:
        """Every row, every field, as the CSV writes it."""
        return [{name: csv_text(row.get(name)) for name in self.fields} for row in self.rows]

    def markdown(self, where: Callable[[Row], bool] | None = None,
                 columns: Sequence[Column] | None = None) -> str:
        """One line per row (those ``where`` accepts), :attr:`columns` (or ``columns``)."""
        columns = self.columns if columns is None else tuple(columns)
        rows = [row for row in self.rows if where is None or where(row)]
        return markdown_table([column.header for column in columns],
                              [[column.text(row) for column in columns] for row in rows])

    def pivot_markdown(self, index: str | Callable[[Row], Value], pivot: str,
                       text: Callable[[Row], str], *, header: str,
                       lines: Sequence[Value] | None = None,
                       pivots: Sequence[Value] | None = None, missing: str = EMPTY_CELL,
                       where: Callable[[Row], bool] | None = None) -> str:
        """One line per value of ``index`` (a field, or a function of the row; ``lines``, or in
        order of appearance) and one column per value of field ``pivot`` (``pivots``,
        likewise), each cell ``text`` of the row there (``missing`` where there is none)."""
        key = index if callable(index) else (lambda row: row[index])
        rows = [row for row in self.rows if where is None or where(row)]
        lines = list(lines if lines is not None else dict.fromkeys(map(key, rows)))
        pivots = list(pivots if pivots is not None
                      else dict.fromkeys(row[pivot] for row in rows))
        cells = {(key(row), row[pivot]): row for row in rows}
        return markdown_table(
            [header, *map(str, pivots)],
            [[str(line), *(text(cells[line, each]) if (line, each) in cells else missing
                           for each in pivots)] for line in lines])
