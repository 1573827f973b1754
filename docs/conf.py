"""Sphinx configuration of the temporal-torchrl documentation.

Build (from the repository root, warnings as errors, every cross-reference checked)::

    .venv/bin/pip install -e '.[docs]'
    .venv/bin/python -m sphinx -W --keep-going -n -b html docs docs/_build/html

Intersphinx works offline by default: Python's inventory is committed
(``docs/_intersphinx/python3.11.inv``, from Debian's ``python3.11-doc``), and references into
PyTorch, TensorDict, TorchRL, NumPy and Matplotlib, whose inventories cannot be fetched without a
network, stay plain text (``nitpick_ignore_regex`` below names those namespaces, and never the
package's own). ``TEMPORAL_TORCHRL_DOCS_ONLINE=1`` fetches those inventories and checks the
references into them too.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import pkgutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))
os.environ.setdefault("MUJOCO_GL", "egl")  # importing the package must not need a display

import temporal_torchrl  # noqa: E402

project = "temporal-torchrl"
author = "temporal-torchrl maintainers"
copyright = "2026, temporal-torchrl maintainers"  # noqa: A001
release = version = temporal_torchrl.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.intersphinx",
    "sphinx.ext.viewcode",
    "myst_parser",
    "public_names",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = [
    "_build",
    "_intersphinx",
    # The results' scripts and data are linked from the pages, never pages themselves.
    "results/**/*.py",
    "results/**/*.json",
    "results/**/*.csv",
    # A study's per-metric tables: report.md, a page, holds them all.
    "results/*/ras.md",
    "results/*/ttfs.md",
    "results/*/tt50s.md",
    "results/*/aggregates.md",
    "results/*/comparisons.md",
    "results/*/evaluation.md",
    "results/*/table_*.md",
]

# Every reference must resolve; a broken one fails the build (-W).
nitpicky = True
ONLINE = os.environ.get("TEMPORAL_TORCHRL_DOCS_ONLINE", "") not in ("", "0")
intersphinx_mapping = {
    "python": ("https://docs.python.org/3.11", str(DOCS / "_intersphinx" / "python3.11.inv")),
}
# Third-party types the public signatures name and that no inventory here can resolve:
# omegaconf.DictConfig (the recipe's config; omegaconf.dictconfig.DictConfig in signatures) and
# mujoco.MjModel (mujoco._structs.MjModel). Never the package's own names.
nitpick_ignore_regex = [(r"py:.*", r"(omegaconf|mujoco)(\..*)?"),
                        # dataclass fields' string annotations (the configs), split at a comma
                        (r"py:class", r"dict\[str")]
if ONLINE:
    intersphinx_mapping |= {
        "torch": ("https://docs.pytorch.org/docs/stable", None),
        "tensordict": ("https://docs.pytorch.org/tensordict/stable", None),
        "torchrl": ("https://docs.pytorch.org/rl/stable", None),
        "numpy": ("https://numpy.org/doc/stable", None),
        "matplotlib": ("https://matplotlib.org/stable", None),
    }
else:
    # Offline (the default, and CI): the inventories that cannot be fetched and of which no
    # copy exists to commit; links into them stay plain text.
    nitpick_ignore_regex += [(r"py:.*", r"(torch|tensordict|torchrl|numpy|matplotlib)(\..*)?")]

# -- autodoc / autosummary / napoleon -------------------------------------------------------------

autosummary_generate = True
autosummary_ignore_module_all = False  # a package's public names are its __all__
autosummary_imported_members = True
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autodoc_inherit_docstrings = False  # torch's and TorchRL's docstrings are theirs to render
autodoc_class_signature = "separated"
python_use_unqualified_type_names = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_attr_annotations = True
napoleon_use_ivar = True  # a class's Attributes section as fields: its members are documented

# Packages documented by their __all__. Each of their modules gets a page too: its docstring (the
# design notes it carries), then what the package does not re-export: public classes and
# functions defined there and the constants documented there with a ``#:`` comment.
PACKAGES = [
    "temporal_torchrl.envs",
    "temporal_torchrl.encoders",
    "temporal_torchrl.transforms",
    "temporal_torchrl.rewards",
    "temporal_torchrl.objectives",
    "temporal_torchrl.data",
    "temporal_torchrl.training",
    "temporal_torchrl.runs",
    "temporal_torchrl.reward_quality",
    "temporal_torchrl.reports",
    "temporal_torchrl.configs",
]
SHORT_VALUE = 60  # constants whose repr is longer are shown without their value


def _submodules(package_name: str) -> list[str]:
    package = importlib.import_module(package_name)
    return sorted(f"{package_name}.{info.name}" for info in pkgutil.iter_modules(package.__path__)
                  if not info.name.startswith("_"))


def _exported_ids(package_name: str) -> set[int]:
    package = importlib.import_module(package_name)
    return {id(getattr(package, name)) for name in package.__all__}


def _defined_constants(module_name: str) -> list[str]:
    """The upper-case names a module assigns at its top level, in source order (not the ones
    it imports)."""
    module = importlib.import_module(module_name)
    tree = ast.parse(inspect.getsource(module))
    names = []
    for statement in tree.body:
        targets = (statement.targets if isinstance(statement, ast.Assign)
                   else [statement.target] if isinstance(statement, ast.AnnAssign) else [])
        for target in targets:
            if (isinstance(target, ast.Name) and target.id.isupper()
                    and not target.id.startswith("_") and target.id not in names):
                names.append(target.id)
    return names


def _constant_entry(module, name: str) -> dict[str, object]:
    return {"name": name, "value": len(repr(getattr(module, name))) <= SHORT_VALUE}


def _module_members(module_name: str) -> dict[str, list]:
    """What a module's page lists besides its docstring: its public classes and functions that
    the package does not re-export, in source order, and its documented constants likewise."""
    module = importlib.import_module(module_name)
    package_name = module_name.rpartition(".")[0]
    exported = _exported_ids(package_name)
    package = importlib.import_module(package_name)
    objects = [name for name, value in vars(module).items()
               if not name.startswith("_") and (inspect.isclass(value) or inspect.isfunction(value))
               and value.__module__ == module_name and id(value) not in exported]
    constants = [_constant_entry(module, name) for name in _defined_constants(module_name)
                 if getattr(package, name, None) is not getattr(module, name)]
    return {"objects": objects, "constants": constants}


def _package_constants(package_name: str) -> list[dict[str, object]]:
    """The constants among a package's ``__all__`` (autosummary lists only its classes,
    exceptions and functions)."""
    package = importlib.import_module(package_name)
    return [_constant_entry(package, name) for name in package.__all__ if not (
        inspect.isclass(getattr(package, name)) or inspect.isroutine(getattr(package, name))
        or inspect.ismodule(getattr(package, name)))]


autosummary_context = {
    "package_constants": {package: _package_constants(package) for package in PACKAGES},
    "submodules": {package: _submodules(package) for package in PACKAGES},
    "module_members": {module: _module_members(module)
                       for package in PACKAGES for module in _submodules(package)},
}

# -- MyST -----------------------------------------------------------------------------------------

myst_enable_extensions = ["colon_fence", "deflist", "attrs_inline"]
myst_heading_anchors = 3

# -- HTML -----------------------------------------------------------------------------------------

html_theme = "furo"
html_title = f"temporal-torchrl {release}"
html_static_path = ["_static"]


def _constant_docstring(app, what, name, obj, options, lines):
    """A constant re-exported by a package keeps the ``#:`` comment of the module that
    defines it (autodoc looks for it in the package's ``__init__`` only, then falls back to the
    docstring of the value's type, ``dict``'s for a dict)."""
    if what != "data":
        return
    type_doc = inspect.getdoc(type(obj)) or ""
    if type_doc and " ".join(" ".join(lines).split()) == " ".join(type_doc.split()):
        lines.clear()  # an undocumented constant: say nothing rather than str's docstring
    package_name, _, attribute = name.rpartition(".")
    if package_name not in PACKAGES:
        return
    from sphinx.pycode import ModuleAnalyzer

    lines.clear()
    for module_name in _submodules(package_name):
        module = importlib.import_module(module_name)
        if getattr(module, attribute, None) is not obj:
            continue
        docs = ModuleAnalyzer.for_module(module_name).find_attr_docs().get(("", attribute))
        if docs:
            lines.extend(docs)
            return


def _keep_subclass_hooks(app, what, name, obj, skip, options):
    """Document the private methods a subclass must implement (``Encoder._encode_text``)."""
    if name in SUBCLASS_HOOKS and getattr(obj, "__doc__", None):
        return False
    return None


def _public_bases(app, name, obj, options, bases):
    """Show a private base class as the public classes it derives from."""
    index = 0
    while index < len(bases):
        base = bases[index]
        if getattr(base, "__name__", "").startswith("_") and base.__module__.startswith(
                "temporal_torchrl"):
            bases[index:index + 1] = list(base.__bases__)
        else:
            index += 1


SUBCLASS_HOOKS = {"_encode_text"}


def _no_inline_type(app, what, name, obj, options, lines):
    """Napoleon reads ``type: description`` into the first line of an attribute's, constant's
    or property's docstring; this package writes prose there ("Files the lock itself writes:
    ..."), so an empty RST comment goes first, which napoleon takes for the line it reads a type
    from. Runs before napoleon."""
    if what in {"attribute", "data", "property"} and lines and ":" in lines[0]:
        lines[:0] = ["..", ""]


def _per_task_results_are_orphans(app, docname, source):
    """The per-task result pages are linked from results.md's table, not listed in the
    navigation (sixty entries of the same few titles); mark them orphans so Sphinx knows."""
    if docname.startswith("results/") and docname.endswith("/results"):
        source[0] = "---\norphan: true\n---\n" + source[0]


def setup(app):
    app.connect("source-read", _per_task_results_are_orphans)
    app.connect("autodoc-process-docstring", _constant_docstring, priority=400)
    app.connect("autodoc-process-docstring", _no_inline_type, priority=450)
    app.connect("autodoc-skip-member", _keep_subclass_hooks)
    app.connect("autodoc-process-bases", _public_bases)
