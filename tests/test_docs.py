"""The documentation's commands and included code stay true, without running them:

- every recipe command in a page's ``bash`` blocks or inline code (README, guides, results
  pages) composes with its recipe's Hydra config *and* passes that recipe's checks (the
  schema's ranges and the rules: ``validate_recipe_config``, ``validate_reward_quality_config``),
  and every ``report.py`` command parses;
- every inline ``key=value`` span (``train.device=auto``, ``-m env.seed=0,1,2,3``) names keys
  of a recipe config and values that pass its checks (``<placeholders>`` only need the key);
- every ``literalinclude`` names a file and markers that exist, and results shown in a code
  block are included from a committed file, never typed in;
- the lists the pages give of what the code writes (``summary.json``'s keys, the line the
  recipe prints) are the code's;
- the Python blocks of the README's composing section and of the adding-a-task guide run.

The site itself is built in CI (``.ci/run``), warnings as errors."""

import ast
import re
import shlex
import sys
from pathlib import Path

import pytest
import report
import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf, open_dict

from temporal_torchrl.configs import RecipeConfig, RewardQualityConfig
from temporal_torchrl.configs.rules import validate_recipe_config, validate_reward_quality_config
from temporal_torchrl.rewards.registry import REWARDS, unregister_reward

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
RECIPES = ROOT / "recipes"
PAGES = [ROOT / "README.md", *sorted(path for path in DOCS.rglob("*.md")
                                     if "_build" not in path.parts)]
#: Scripts whose arguments are Hydra overrides, and the config they compose.
CONFIGS = {"recipes/sac_temporal.py": "config", "recipes/evaluate_rewards.py": "evaluate_rewards",
           "docs/results/beyond_thesis/calibrate_certainty.py": "evaluate_rewards",
           "docs/results/beyond_thesis/reward_shape.py": "evaluate_rewards",
           "docs/results/beyond_thesis/sequence_encoders.py": "evaluate_rewards"}
VALIDATE = {"config": validate_recipe_config, "evaluate_rewards": validate_reward_quality_config}
SCRIPTS = (*CONFIGS, "recipes/report.py")
#: The first part of a key the recipes' configs know (``train`` of ``train.device=auto``).
HEADS = ({spec for schema in (RecipeConfig, RewardQualityConfig)
          for spec in schema.__dataclass_fields__} | {"preset", "protocol", "study", "hydra"})
OVERRIDE = re.compile(r"['\"]?[+~]?([a-z_]+)[\w./]*=\S*")
PLACEHOLDER = re.compile(r"<[^<>`]*>|\.\.\.|\bN\b")


def relative(page: Path) -> str:
    return str(page.relative_to(ROOT))


def shell_commands(page: Path) -> list[str]:
    """The commands of a page's ``bash`` blocks: continuation lines joined, comments dropped,
    ``$VAR`` replaced by a ``VAR=...`` assignment of the same block."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.DOTALL):
        variables: dict[str, str] = {}
        for line in block.replace("\\\n", " ").splitlines():
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            assignment = re.fullmatch(r"(\w+)=(.*)", line.strip())
            if assignment:
                variables[assignment[1]] = shlex.split(assignment[2])[0]
                continue
            for name, value in variables.items():
                line = re.sub(rf'"?\${name}"?', lambda _, v=value: shlex.quote(v), line)
            commands.append(line)
    return commands


def inline_spans(page: Path) -> list[str]:
    """The page's inline code spans, outside fenced blocks."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    return re.findall(r"(?<!`)`([^`\n]+)`(?!`)", text)


def script_commands() -> list[tuple[str, str, list[str]]]:
    """(page, script, arguments) of every command that runs one of ``SCRIPTS``, in a bash block
    or an inline span."""
    found = []
    for page in PAGES:
        for command in shell_commands(page) + [span for span in inline_spans(page)
                                                if re.match(r"(\S*/)?python3? ", span)]:
            try:
                words = shlex.split(PLACEHOLDER.sub("PLACEHOLDER", command), comments=True)
            except ValueError:
                continue
            for index, word in enumerate(words):
                if word in SCRIPTS:
                    found.append((relative(page), word, words[index + 1:]))
                    break
    return found


def override_spans() -> list[tuple[str, str]]:
    """(page, span) of every inline span made only of recipe overrides (and ``-m``)."""
    found = []
    for page in PAGES:
        for span in inline_spans(page):
            words = PLACEHOLDER.sub("PLACEHOLDER", span).split()
            if words and all(word == "-m" or ((match := OVERRIDE.fullmatch(word))
                                              and match[1] in HEADS) for word in words) and (
                    words != ["-m"]):
                found.append((relative(page), span))
    return sorted(set(found))


COMMANDS = script_commands()
SPANS = override_spans()


def single_run(arguments: list[str]) -> tuple[list[str], bool]:
    """A ``-m`` sweep's first job: each swept key at its first value (Hydra's ``--cfg <part>``
    left out)."""
    multirun = "-m" in arguments
    if "--cfg" in arguments:  # Hydra's own flag (print the config): it and its value go
        index = arguments.index("--cfg")
        arguments = arguments[:index] + arguments[index + 2:]
    overrides = [argument for argument in arguments if argument != "-m"]
    parsed = OverridesParser.create().parse_overrides(overrides)
    first = [f"{override.get_key_element()}={next(override.sweep_string_iterator())}"
             if override.is_sweep_override() else text
             for override, text in zip(parsed, overrides, strict=True)]
    return first, multirun


def checked(config_name: str, overrides: list[str]):
    """The config ``overrides`` compose to, checked as the recipe checks it before a run. CUDA
    counts as present: a GPU command is checked on a CPU-only machine too."""
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose(config_name, overrides=overrides, return_hydra_config=True)
    HydraConfig.instance().set_config(cfg)  # as in a run: ${hydra:sweep.dir} resolves
    with open_dict(cfg):
        del cfg["hydra"]
    registered, loaded = set(REWARDS), set(sys.modules)
    try:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(torch.cuda, "is_available", lambda: True)
            return VALIDATE[config_name](cfg)
    finally:  # a command's reward.modules register rewards: the other tests see the built-ins
        HydraConfig.instance().cfg = None
        for name in set(REWARDS) - registered:
            unregister_reward(name)
        for name in set(sys.modules) - loaded:
            if name.startswith("reward_module_"):
                del sys.modules[name]


def test_the_pages_have_commands_and_spans():
    scripts = {script for _, script, _ in COMMANDS}
    assert {"recipes/sac_temporal.py", "recipes/evaluate_rewards.py",
            "recipes/report.py"} <= scripts
    assert len(SPANS) >= 30
    assert ("docs/guides/protocols.md", "protocol=stage2") in SPANS


@pytest.mark.parametrize(("page", "script", "arguments"),
                         [command for command in COMMANDS if command[1] in CONFIGS],
                         ids=lambda value: value if isinstance(value, str) else None)
def test_recipe_command_composes_and_passes_the_checks(page, script, arguments):
    error = refused(arguments, [CONFIGS[script]])
    assert error is None, f"{page}: {script} {' '.join(arguments)}\n{error}"


@pytest.mark.parametrize(("page", "arguments"),
                         [(page, arguments) for page, script, arguments in COMMANDS
                          if script == "recipes/report.py"])
def test_report_command_parses(page, arguments):
    assert report.parse_args(arguments).out


def refused(words: list[str], config_names: list[str]) -> str | None:
    """None when one of ``config_names`` accepts the overrides ``words`` (a ``-m`` sweep: its
    first job; a ``PLACEHOLDER`` value: its key must exist), else why each refused them."""
    overrides, _ = single_run(words)
    concrete = [word for word in overrides if "PLACEHOLDER" not in word]
    keys = [word.split("=")[0].lstrip("+~") for word in overrides if "PLACEHOLDER" in word]
    errors = []
    for config_name in config_names:
        try:
            cfg = checked(config_name, concrete)
        except Exception as error:  # noqa: BLE001 (a config may refuse it; all of them is the fail)
            errors.append(f"{config_name}: {error}")
            continue
        missing = [key for key in keys if OmegaConf.select(cfg, key, default=KeyError) is KeyError]
        if not missing:
            return None
        errors.append(f"{config_name}: no key {missing}")
    return "\n".join(errors)


@pytest.mark.parametrize(("page", "span"), SPANS)
def test_inline_override_names_keys_and_values_a_recipe_accepts(page, span):
    """A span is checked against the training recipe's config, or, where that refuses it, the
    reward-quality recipe's (``finetune.updates=100``)."""
    error = refused(shlex.split(PLACEHOLDER.sub("PLACEHOLDER", span)),
                    ["config", "evaluate_rewards"])
    assert error is None, f"{page}: `{span}` is refused by both recipes:\n{error}"


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


def test_results_in_code_blocks_are_included_not_typed():
    """A table inside a code fence of a hand-written page looks like output: it must come from a
    committed file (``literalinclude``), so it cannot be invented or go stale."""
    hand_written = [ROOT / "README.md", *sorted((DOCS / "guides").glob("*.md")),
                    *sorted(DOCS.glob("*.md"))]
    for page in hand_written:
        for block in re.findall(r"```([^\n]*)\n(.*?)```", page.read_text(), flags=re.DOTALL):
            if "|---" in block[1]:
                assert block[0].startswith("{literalinclude}"), f"{page.name}: {block[1][:80]}"


def test_every_example_is_in_a_guide():
    included = {path.name for _, path, _ in literalincludes()}
    examples = {path.name for path in (ROOT / "examples").iterdir()
                if path.suffix in {".py", ".sh"}}
    assert examples <= included, examples - included


def _returned_dict_keys(path: Path, function: str) -> dict[str, list[str]]:
    """The string keys of the dict literal ``function`` returns, and of its dict values."""
    tree = ast.parse(path.read_text())
    node = next(node for node in ast.walk(tree)
                if isinstance(node, ast.FunctionDef) and node.name == function)
    returned = next(item.value for item in ast.walk(node) if isinstance(item, ast.Return))
    keys = {"": [key.value for key in returned.keys]}
    for key, value in zip(returned.keys, returned.values, strict=True):
        if isinstance(value, ast.Dict):
            keys[key.value] = [item.value for item in value.keys]
    return keys


def test_the_recipe_guide_lists_the_keys_summary_json_has():
    keys = _returned_dict_keys(ROOT / "temporal_torchrl" / "training" / "summary.py",
                               "run_summary")
    listed = (DOCS / "guides" / "recipe.md").read_text().split("<!-- summary-keys -->")[1]
    listed = listed.split("<!-- /summary-keys -->")[0]
    named = re.findall(r"`(\w+)`", listed)
    assert [key for key in named if key not in keys["ras"]] == keys[""]
    assert set(keys["ras"]) <= set(named)


def test_the_readme_shows_the_line_the_recipe_prints():
    """The README's "what you will see" summary line has the keys ``recipes/sac_temporal.py``
    prints, in its order."""
    tree = ast.parse((RECIPES / "sac_temporal.py").read_text())
    run = next(node for node in ast.walk(tree)
               if isinstance(node, ast.FunctionDef) and node.name == "run")
    printed = next(node for node in ast.walk(run) if isinstance(node, ast.Tuple)
                   and all(isinstance(item, ast.Constant) for item in node.elts)
                   and node.elts[0].value == "ttfs")
    line = next(line for line in (ROOT / "README.md").read_text().splitlines()
                if line.startswith("{'ttfs'"))
    assert list(ast.literal_eval(line)) == [item.value for item in printed.elts]


def test_the_adding_a_task_guide_runs():
    blocks = re.findall(r"```python\n(.*?)```", (DOCS / "guides" / "adding-a-task.md").read_text(),
                        flags=re.DOTALL)
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], "adding-a-task.md", "exec"), namespace)
    spec = namespace["spec"]
    assert (spec.tailored_baseline, spec.ras_budget) == (None, None)
    assert spec.goal_prompt in blocks[0]  # the printed line shown is the prompt


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


def _default_words(cell: str) -> list[str]:
    """The defaults a row of the recipe guide's table states, one per key: ``1e-4, 256``."""
    return [word.strip().strip("`") for word in cell.split(", ")]


def _as_written(value) -> str:
    """A default as the guide writes it: ``null``, ``true``, ``1e-4``, ``1,000``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.0e}".replace("e-0", "e-") if 0 < value < 1e-3 else str(value)
    if isinstance(value, int):
        return f"{value:,}"
    return str(value)


def test_the_recipe_guides_table_of_defaults_is_the_schemas():
    """Every default the recipe guide's key table states is the composed default config's (the
    schema's, and for preset and protocol config.yaml's defaults list)."""
    page = (DOCS / "guides" / "recipe.md").read_text()
    rows = [line.split(" | ") for line in page.splitlines()
            if line.startswith("| `") and line.count(" | ") >= 3]
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = OmegaConf.to_container(compose("config", return_hydra_config=True), resolve=True)
    choices = cfg["hydra"]["runtime"]["choices"]
    checked = []
    for row in rows:
        keys = re.findall(r"`([\w.]+)`", row[0])
        defaults = _default_words(row[1])
        assert len(keys) == len(defaults), row
        for key, written in zip(keys, defaults, strict=True):
            if key in choices:
                actual = choices[key]
            else:
                actual = OmegaConf.select(OmegaConf.create(cfg), key)
            assert written == _as_written(actual), f"{key}: the guide says {written}"
            checked.append(key)
    assert len(checked) >= 30 and {"preset", "train.episodes", "sac.lr"} <= set(checked)
