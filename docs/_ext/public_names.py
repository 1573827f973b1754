"""Resolve the package's cross-references to the names they are documented under.

The API reference documents each object once, under its public name: the package that
re-exports it (``temporal_torchrl.rewards.TemporalReward``, not
``temporal_torchrl.rewards.temporal.TemporalReward``). Docstrings name objects the way their
module sees them: ``:func:`episode_rows``` inside ``temporal_torchrl.data.episodes``,
``:func:`~temporal_torchrl.rewards.positional.goal_baseline_regularise``` from elsewhere. When
Sphinx cannot resolve such a reference, this extension imports what it names (relative to the
referencing object's module and class, or to the object an autosummary row summarises) and,
when that is an object documented under another name, links it there.

Nothing else is resolved: a reference to a name that does not exist, or to an object the
reference does not document, still fails the build (``nitpicky``, ``-W``).
"""

from __future__ import annotations

import importlib
from typing import Any

from docutils import nodes
from sphinx.addnodes import pending_xref

PACKAGE = "temporal_torchrl"
_MISSING = object()


def _import(path: str) -> Any:
    """The object a dotted path names (module, then attributes), or ``_MISSING``."""
    parts = path.split(".")
    for split in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:split]))
        except ImportError:
            continue
        for attribute in parts[split:]:
            obj = getattr(obj, attribute, _MISSING)
            if obj is _MISSING:
                return _MISSING
        return obj
    return _MISSING


class PublicNames:
    """``id(object) -> documented name`` for every object the Python domain documents."""

    def __init__(self, documented: dict[str, Any]) -> None:
        self.documented = documented
        self._by_id: dict[int, str] = {}
        for name in sorted(documented, key=lambda name: name.count(".")):
            if not name.startswith(PACKAGE + "."):
                continue
            obj = _import(name)
            # Plain values (ints, strings) are shared by unrelated names: only objects with an
            # identity of their own are mapped.
            if obj is not _MISSING and not isinstance(obj, int | float | str | bytes | bool):
                self._by_id.setdefault(id(obj), name)

    def documented_name(self, path: str) -> str | None:
        """The documented name of what ``path`` names, trying its longest importable prefix
        that is documented under another name (``Class.method`` keeps its method part)."""
        if path in self.documented:
            return path
        parts = path.split(".")
        for split in range(len(parts), 0, -1):
            obj = _import(".".join(parts[:split]))
            if obj is _MISSING:
                continue
            public = self._by_id.get(id(obj))
            if public is None:
                continue
            candidate = ".".join([public, *parts[split:]])
            if candidate in self.documented:
                return candidate
        # A constant (a plain value: no identity to go by) re-exported under its own name by a
        # package above its module: ``temporal_torchrl.runs.layout.METRICS_FILE`` is
        # ``temporal_torchrl.runs.METRICS_FILE``.
        module_path, _, attribute = path.rpartition(".")
        value = _import(path)
        while value is not _MISSING and "." in module_path:
            module_path = module_path.rpartition(".")[0]
            candidate = f"{module_path}.{attribute}"
            if candidate in self.documented and _import(candidate) is value:
                return candidate
        return None


def _contexts(node: pending_xref) -> list[str]:  # noqa: C901
    """Where a relative name is looked up, most specific first: the referencing object's class
    and module (and the module that defines it), or the object an autosummary row is about."""
    module, cls = node.get("py:module"), node.get("py:class")
    contexts = []
    if module and cls:
        contexts.append(f"{module}.{cls}")
        owner = _import(f"{module}.{cls}")
        if owner is not _MISSING and getattr(owner, "__module__", None):
            contexts.append(f"{owner.__module__}.{cls}")
            contexts.append(owner.__module__)
    row = node.parent
    while row is not None and not isinstance(row, nodes.row):
        row = row.parent
    if row is not None:
        # The row's first cell names the object (a reference once Sphinx resolved it).
        first = next(iter(row.findall(lambda n: isinstance(n, pending_xref | nodes.reference))),
                     None)
        summarised = ""
        if isinstance(first, pending_xref) and first is not node:
            summarised = first.get("reftarget", "")
        elif isinstance(first, nodes.reference):
            summarised = first.get("reftitle", "")
        if summarised:
            obj = _import(summarised)
            contexts.append(summarised)
            if obj is not _MISSING and getattr(obj, "__module__", None):
                contexts.append(f"{obj.__module__}.{summarised.rpartition('.')[2]}")
                contexts.append(obj.__module__)
            contexts.append(summarised.rpartition(".")[0])
    # A generated API page is named after the object it documents: its module and class are
    # where the object's own docstring names things.
    page = _import(node.get("refdoc", "").rpartition("/")[2])
    if page is not _MISSING:
        if isinstance(page, type):
            contexts.append(f"{page.__module__}.{page.__qualname__}")
        if getattr(page, "__module__", None):
            contexts.append(page.__module__)
    if module:
        contexts.append(module)
    return contexts


def resolve(app, env, node: pending_xref, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    if not target or target.split(".")[0] in {"torch", "tensordict", "torchrl"}:
        return None
    domain = env.get_domain("py")
    names = app.env.temp_data.setdefault("public_names", None)
    if names is None or len(names.documented) != len(domain.objects):
        names = PublicNames({**domain.objects, **domain.modules})
        app.env.temp_data["public_names"] = names
    candidates = [target] if target.startswith(PACKAGE + ".") else []
    candidates += [f"{context}.{target}" for context in _contexts(node)]
    for candidate in candidates:
        name = names.documented_name(candidate)
        if name is None:
            continue
        resolved = domain.resolve_xref(env, node.get("refdoc", ""), app.builder,
                                       node["reftype"], name, node, contnode)
        if resolved is None:
            resolved = domain.resolve_any_xref(env, node.get("refdoc", ""), app.builder,
                                               name, node, contnode)
            resolved = resolved[0][1] if resolved else None
        if resolved is not None:
            return resolved
    return None


def setup(app):
    app.connect("missing-reference", resolve)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
