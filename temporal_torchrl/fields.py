"""A config key's simple range, declared once next to its type: :func:`constrained` fields.

OmegaConf checks a key's type (``int``, ``float``, ``bool``, ``str``, lists, ``| None``) but has
no ranges or choices; :func:`constrained` records them in the dataclass field's metadata, where
:func:`temporal_torchrl.configs.rules.check_constraints` reads them for every key of a schema.
"""

from __future__ import annotations

import dataclasses
import numbers
import types
import typing
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


def field_of(params: type, name: str) -> Any:
    """A dataclass field with the default and range of ``params``'s field ``name``: a config
    schema that keeps a key under its own name (``train.relay_noise``) takes both from the
    parameter object's field (``RelayParams.noise``), where they are written once.

    >>> @dataclasses.dataclass
    ... class Params:
    ...     steps: int = constrained(500, ge=1)
    >>> @dataclasses.dataclass
    ... class Config:
    ...     params_steps: int = field_of(Params, "steps")
    >>> Config().params_steps, dataclasses.fields(Config)[0].metadata[CONSTRAINT].ge
    (500, 1)
    """
    spec = next(spec for spec in dataclasses.fields(params) if spec.name == name)
    if spec.default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=spec.default_factory, metadata=spec.metadata)
    return dataclasses.field(default=spec.default, metadata=spec.metadata)


#: The words for a field's type in :func:`check_fields`' errors.
_NOUNS = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}


def check_fields(instance: Any) -> None:
    """Refuse (``ValueError``, naming the class, the field and what it takes) a dataclass
    instance whose :func:`constrained` fields are out of range, or whose ``int``, ``float`` or
    ``bool`` fields hold another type: the checks a config key gets, for an object built in
    code.

    >>> @dataclasses.dataclass
    ... class Example:
    ...     steps: int = constrained(500, ge=1)
    ...     def __post_init__(self):
    ...         check_fields(self)
    >>> Example(steps=0)
    Traceback (most recent call last):
    ...
    ValueError: Example: steps=0; expected an integer >= 1.
    """
    hints = typing.get_type_hints(type(instance))
    for spec in dataclasses.fields(instance):
        value = getattr(instance, spec.name)
        if value is None:
            continue
        kind = _item_type(hints[spec.name])
        constraint = spec.metadata.get(CONSTRAINT)
        items = list(value) if isinstance(value, (list, tuple)) else [value]
        noun = _NOUNS.get(kind, "a value")
        expected = constraint.describe(noun) if constraint is not None else noun
        if isinstance(value, (list, tuple)):
            nonempty = "non-empty " if constraint is not None and constraint.nonempty else ""
            expected = f"a {nonempty}list, each item {expected}"
        if ((kind in (int, float, bool) and not all(_is(item, kind) for item in items))
                or (constraint is not None and ((constraint.nonempty and not items)
                                                or not all(map(constraint.admits, items))))):
            raise ValueError(f"{type(instance).__name__}: {spec.name}={value!r}; expected "
                             f"{expected}.")


def _item_type(annotation: Any) -> Any:
    """The type of a field's value, or of each item of a list: ``int | None`` -> ``int``;
    ``list[int]`` -> ``int``; others as they are."""
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        annotation = next(arg for arg in typing.get_args(annotation) if arg is not type(None))
    if typing.get_origin(annotation) is list:
        return typing.get_args(annotation)[0]
    return annotation


def _is(value: Any, kind: type) -> bool:
    """Whether ``value`` is a ``kind``, as a config key of that type would be (an int is a
    float, a bool is neither)."""
    if kind is bool:
        return isinstance(value, bool)
    if isinstance(value, bool):
        return False
    return isinstance(value, numbers.Real if kind is float else numbers.Integral)
