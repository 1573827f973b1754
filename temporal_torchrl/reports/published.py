"""The thesis's published results (Tables 5.2-5.12), as data, matched to run configurations.

The values live in ``published_tables.yaml`` next to this module, transcribed from the thesis
text with the table number, the metric and, for every column, the configuration it was run with
(:class:`Configuration`). A run group matches a column when its config describes the same
configuration: the same positional and directional rewards, rho, lambda (with a directional
reward), baseline (for the rewards that read it; "unstated" in the thesis matches either), alpha
(for P3, P4, D5) and protocol. Nothing else is compared: the thesis ran LIV; runs with another
encoder are matched too, and the report says so.

Example:
    >>> from temporal_torchrl.reports.published import Configuration, find_published
    >>> furl = Configuration("furl", None, rho=0.05, protocol="stage2")
    >>> result = find_published(furl, "ras")
    >>> result.tables, result.cells["drawer-open"].mean
    (('5.4', '5.5', '5.6'), 41.7)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from temporal_torchrl.reports.groups import uses_baseline
from temporal_torchrl.rewards.config import none_or_name
from temporal_torchrl.runs.layout import protocol_name

DATA_FILE = Path(__file__).with_name("published_tables.yaml")
#: The thesis's encoder for every published value.
PUBLISHED_ENCODER = "liv"
#: A column's baseline the thesis does not state (Tables 5.2, 5.3): matches either.
UNSTATED = "unstated"
#: Rewards that read alpha (goal-baseline regularisation).
ALPHA_POSITIONAL = ("p3", "p4")
ALPHA_DIRECTIONAL = ("d5",)


@dataclass(frozen=True)
class Configuration:
    """What the thesis's tables vary, with the fields a reward does not read set to None.

    Attributes:
        positional, directional: reward variant names (``"furl"``, ``"p2"``, ``"d3"``), or None.
        rho: the VLM reward weight (None without a VLM reward).
        lambda_: the directional weight (None without a directional reward).
        baseline: ``"generic"``, ``"tailored"`` or a text (None for rewards that do not read
            it; ``"unstated"`` in a published column that does not say).
        alpha: goal-baseline regularisation strength (None unless P3, P4 or D5).
        protocol: ``"stage1"`` (no preloaded episodes) or ``"stage2"`` (50 experts).
    """

    positional: str | None
    directional: str | None
    rho: float | None = None
    lambda_: float | None = None
    baseline: str | None = None
    alpha: float | None = None
    protocol: str = "stage2"

    @classmethod
    def from_fields(cls, fields: Mapping[str, Any]) -> Configuration:
        """Build from reward fields (published columns, or a run's settings), dropping what the
        reward does not read so that equal rewards compare equal."""
        positional = none_or_name(fields.get("positional"))
        directional = none_or_name(fields.get("directional"))
        vlm = positional is not None or directional is not None
        alpha = positional in ALPHA_POSITIONAL or directional in ALPHA_DIRECTIONAL
        return cls(positional, directional,
                   rho=float(fields["rho"]) if vlm else None,
                   lambda_=float(fields["lambda_"]) if directional is not None else None,
                   baseline=(fields["baseline"] if uses_baseline(positional, directional)
                             else None),
                   alpha=float(fields["alpha"]) if alpha else None,
                   protocol=fields["protocol"])

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any]) -> Configuration:
        """The configuration of a run group's flattened settings (``reward.rho``, ...)."""
        fields = {key.removeprefix("reward."): value for key, value in settings.items()
                  if key.startswith("reward.")}
        fields["protocol"] = protocol_name(settings.get("train.preload_positives", 0))
        return cls.from_fields(fields)

    def matches(self, run: Configuration) -> bool:
        """Whether this (published) configuration is the ``run``'s."""
        def same(published: Any, measured: Any) -> bool:
            if isinstance(published, float) and isinstance(measured, float):
                return math.isclose(published, measured)
            return published == measured

        return (self.positional == run.positional and self.directional == run.directional
                and same(self.rho, run.rho) and same(self.lambda_, run.lambda_)
                and same(self.alpha, run.alpha) and self.protocol == run.protocol
                and (self.baseline == UNSTATED or self.baseline == run.baseline))


@dataclass(frozen=True)
class PublishedCell:
    """One published value: the mean over the thesis's 4 seeds and, where printed, the std."""

    mean: float
    std: float | None = None

    @classmethod
    def parse(cls, text: str) -> PublishedCell:
        """``"379 ± 214"`` or ``"53.5"``."""
        mean, _, std = str(text).partition("±")
        return cls(float(mean), float(std) if std.strip() else None)


@dataclass(frozen=True)
class PublishedColumn:
    label: str
    configuration: Configuration


@dataclass(frozen=True)
class PublishedTable:
    """One table of the thesis: ``rows[task][column]`` and the ``average`` row."""

    number: str
    metric: str
    caption: str
    columns: tuple[PublishedColumn, ...]
    rows: dict[str, tuple[PublishedCell, ...]]
    average: tuple[float, ...]


@functools.cache
def published_tables() -> tuple[PublishedTable, ...]:
    """The thesis's Tables 5.2-5.12 (read once from :data:`DATA_FILE`)."""
    data = yaml.safe_load(DATA_FILE.read_text(encoding="utf-8"))
    tables = []
    for table in data["tables"]:
        columns = tuple(PublishedColumn(column["label"], Configuration.from_fields(column))
                        for column in table["columns"])
        rows = {task: tuple(map(PublishedCell.parse, cells))
                for task, cells in table["rows"].items()}
        if any(len(cells) != len(columns) for cells in rows.values()) \
                or len(table["average"]) != len(columns):
            raise ValueError(f"{DATA_FILE}: table {table['table']} has rows or an average of "
                             f"another length than its {len(columns)} columns.")
        tables.append(PublishedTable(str(table["table"]), table["metric"], table["caption"],
                                     columns, rows, tuple(map(float, table["average"]))))
    return tuple(tables)


@dataclass(frozen=True)
class PublishedResult:
    """The published values of one configuration and metric, merged over the tables that
    print it (SAC, for one, appears in seven).

    Attributes:
        tables: the table numbers, e.g. ``("5.4", "5.5")``.
        cells: task -> value.
        average: the thesis's Average row (over its six tasks).
        baseline_unstated: the thesis does not say which baseline this column used.
    """

    tables: tuple[str, ...]
    cells: dict[str, PublishedCell]
    average: float
    baseline_unstated: bool


def find_published(configuration: Configuration, metric: str) -> PublishedResult | None:
    """The thesis's values of ``metric`` (``"ras"``, ``"ttfs"``, ``"tt50s"``) for a run
    configuration, or None when no published column matches.

    Raises ``ValueError`` if two matching tables print different values (a transcription
    error: the thesis repeats its baselines with the same numbers).
    """
    matches = [(table, index) for table in published_tables() if table.metric == metric
               for index, column in enumerate(table.columns)
               if column.configuration.matches(configuration)]
    if not matches:
        return None
    first, first_index = matches[0]
    for table, index in matches[1:]:
        if any(table.rows[task][index] != cells[first_index]
               for task, cells in first.rows.items()) \
                or table.average[index] != first.average[first_index]:
            raise ValueError(f"published tables {first.number} and {table.number} disagree on "
                             f"{configuration}; check {DATA_FILE.name}.")
    return PublishedResult(
        tables=tuple(table.number for table, _ in matches),
        cells={task: cells[first_index] for task, cells in first.rows.items()},
        average=first.average[first_index],
        baseline_unstated=any(table.columns[index].configuration.baseline == UNSTATED
                              for table, index in matches))
