"""A config key's simple range, declared once next to its type: :func:`constrained` fields.

OmegaConf checks a key's type (``int``, ``float``, ``bool``, ``str``, lists, ``| None``) but has
no ranges or choices; :func:`constrained` records them in the dataclass field's metadata, where
:func:`temporal_torchrl.configs.rules.check_constraints` reads them for every key of a schema.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

#: The metadata key under which :func:`constrained` stores a field's :class:`Constraint`.
CONSTRAINT = "constraint"


@dataclasses.dataclass(frozen=True)
class Constraint:
    """What a key's value (each item of a list value) must be, beyond its type.

    ``ge``/``gt``/``le``/``lt``: bounds; ``choices``: the values allowed; ``nonempty``: a list
    value needs at least one item.
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple[Any, ...] | None = None
    nonempty: bool = False

    def admits(self, value: Any) -> bool:
        """Whether one value (or list item) meets the bounds and choices."""
        if self.choices is not None:
            return value in self.choices
        return ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))

    def describe(self, noun: str) -> str:
        """``noun`` (``an integer``, ``a number``...) with the range: ``an integer >= 1``,
        ``a number in (0, 1]``; ``one of a, b`` for choices."""
        if self.choices is not None:
            return "one of " + ", ".join(str(choice) for choice in self.choices)
        low = next(((sign, bracket, bound) for sign, bracket, bound in
                    ((">=", "[", self.ge), (">", "(", self.gt)) if bound is not None), None)
        high = next(((sign, bracket, bound) for sign, bracket, bound in
                     (("<=", "]", self.le), ("<", ")", self.lt)) if bound is not None), None)
        if low is not None and high is not None:
            return f"{noun} in {low[1]}{low[2]:g}, {high[2]:g}{high[1]}"
        if low is not None or high is not None:
            sign, _, bound = low if low is not None else high
            return f"{noun} {sign} {bound:g}"
        return noun


def constrained(default: Any, *, ge: float | None = None, gt: float | None = None,
                le: float | None = None, lt: float | None = None,
                choices: Sequence[Any] | None = None, nonempty: bool = False) -> Any:
    """A dataclass field with ``default`` and a :class:`Constraint` (a list default is copied
    for each instance).

    >>> import dataclasses
    >>> @dataclasses.dataclass
    ... class Example:
    ...     steps: int = constrained(500, ge=1)
    >>> dataclasses.fields(Example)[0].metadata[CONSTRAINT].describe("an integer")
    'an integer >= 1'
    """
    constraint = Constraint(ge=ge, gt=gt, le=le, lt=lt, nonempty=nonempty,
                            choices=tuple(choices) if choices is not None else None)
    metadata = {CONSTRAINT: constraint}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)
