"""The documentation's commands and included code stay true: every ``literalinclude`` names a
file and markers that exist, and every recipe command in the README and the docs' pages
composes with the recipe's Hydra config (or, for ``report.py``, parses), without running it.
The site itself is built in CI (``.ci/run``), warnings as errors."""

import re
import shlex
from pathlib import Path

import pytest
import report
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
RECIPES = ROOT / "recipes"
PAGES = [ROOT / "README.md", *sorted((DOCS / "guides").glob("*.md")), *sorted(DOCS.glob("*.md"))]
CONFIGS = {"sac_temporal.py": "config", "evaluate_rewards.py": "evaluate_rewards"}


def shell_commands(page: Path) -> list[str]:
    """The commands of a page's ``bash`` blocks: continuation lines joined, comments dropped."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.DOTALL):
        for line in block.replace("\\\n", " ").splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                commands.append(line)
    return commands


def recipe_commands() -> list[tuple[str, str, list[str]]]:
    found = []
    for page in PAGES:
        for command in shell_commands(page):
            words = shlex.split(command, comments=True)
            for index, word in enumerate(words):
                if word.startswith(("recipes/", ".venv/bin/python recipes/")) or (
                        word.endswith(".py") and word.startswith("recipes/")):
                    script = Path(word).name
                    found.append((page.name, script, words[index + 1:]))
                    break
    return found


COMMANDS = recipe_commands()


def single_run(arguments: list[str]) -> tuple[list[str], bool]:
    """A ``-m`` sweep's first job: each swept key at its first value."""
    multirun = "-m" in arguments
    overrides = [argument for argument in arguments if argument != "-m"]
    parsed = OverridesParser.create().parse_overrides(overrides)
    first = [f"{override.get_key_element()}={next(override.sweep_string_iterator())}"
             if override.is_sweep_override() else text
             for override, text in zip(parsed, overrides, strict=True)]
    return first, multirun


def test_the_pages_have_recipe_commands():
    scripts = {script for _, script, _ in COMMANDS}
    assert {"sac_temporal.py", "evaluate_rewards.py", "report.py"} <= scripts


@pytest.mark.parametrize(("page", "script", "arguments"),
                         [command for command in COMMANDS if command[1] in CONFIGS],
                         ids=lambda value: value if isinstance(value, str) else None)
def test_recipe_command_composes(page, script, arguments):
    overrides, multirun = single_run(arguments)
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose(CONFIGS[script], overrides=overrides, return_hydra_config=multirun)
    assert cfg.env is not None


@pytest.mark.parametrize(("page", "arguments"),
                         [(page, arguments) for page, script, arguments in COMMANDS
                          if script == "report.py"])
def test_report_command_parses(page, arguments):
    assert report.parse_args(arguments).out


def literalincludes():
    for page in sorted(DOCS.rglob("*.md")):
        if "_build" in page.parts:
            continue
        for match in re.finditer(r"```\{literalinclude\} (\S+)\n(.*?)```", page.read_text(),
                                 flags=re.DOTALL):
            options = dict(re.findall(r':([\w-]+): "?(.*?)"?$', match.group(2), flags=re.M))
            yield page, (page.parent / match.group(1)).resolve(), options


def test_literalincludes_name_files_and_markers_that_exist():
    included = list(literalincludes())
    assert len(included) >= 8
    for page, path, options in included:
        assert path.is_file(), f"{page.name}: {path} does not exist"
        text = path.read_text()
        for option in ("start-after", "end-before"):
            if option in options:
                assert options[option] in text, f"{page.name}: {options[option]!r} not in {path}"


def test_every_example_is_in_a_guide():
    included = {path.name for _, path, _ in literalincludes()}
    examples = {path.name for path in (ROOT / "examples").iterdir()
                if path.suffix in {".py", ".sh"}}
    assert examples <= included, examples - included


def test_the_api_reference_lists_every_package():
    """A new subpackage (or a removed one) shows here, not only in CI's docs build: add it to
    ``PACKAGES`` in docs/conf.py and to docs/api/index.rst."""
    import pkgutil

    import temporal_torchrl

    packages = {f"temporal_torchrl.{info.name}" for info in pkgutil.iter_modules(
        temporal_torchrl.__path__) if info.ispkg}
    conf = (DOCS / "conf.py").read_text()
    listed = set(re.findall(r'"(temporal_torchrl\.\w+)",', conf.split("PACKAGES = [")[1]
                            .split("]")[0]))
    index = set(re.findall(r"^   (temporal_torchrl\.\w+)$", (DOCS / "api" / "index.rst")
                           .read_text(), flags=re.M))
    assert listed == packages, f"docs/conf.py PACKAGES: {sorted(packages ^ listed)}"
    assert packages <= index, f"docs/api/index.rst: {sorted(packages - index)}"
