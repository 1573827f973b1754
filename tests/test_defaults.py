"""The library's shared defaults (temporal_torchrl.defaults) are each written once: the package's
signatures, the recipes' schemas, the reward-quality dataset and the protocol files all read the
one value, so no copy can drift from the others."""

import ast
import dataclasses
from pathlib import Path

from helpers import RECIPES
from omegaconf import OmegaConf

from temporal_torchrl import defaults
from temporal_torchrl.configs.reward_quality import DatasetConfig
from temporal_torchrl.params import EnvParams
from temporal_torchrl.reward_quality import DatasetSpec
from temporal_torchrl.runs.layout import protocol_name

PACKAGE = Path(defaults.__file__).parent


def literal_homes(value: object) -> list[str]:
    """``file:line`` of every literal ``value`` in the package's code (docstrings and comments
    aside: a docstring is one longer string, a comment no literal at all)."""
    homes = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Constant) and type(node.value) is type(value)
                    and node.value == value):
                homes.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    return homes


def test_the_camera_the_goal_setting_and_the_episode_length_are_written_once():
    """``"corner2"``, ``"fixed"`` and the 500 steps appear once, in defaults.py: a signature or
    schema that wrote its own copy would fail here."""
    homes = {value: literal_homes(value) for value in ("corner2", "fixed", 500)}
    assert {value: [home.split(":")[0] for home in found] for value, found in homes.items()} == {
        "corner2": ["defaults.py"], "fixed": ["defaults.py"], 500: ["defaults.py"]}, homes


def test_defaults_imports_nothing():
    """The config schemas import it, and they must stay free of torch."""
    tree = ast.parse((PACKAGE / "defaults.py").read_text())
    assert not [node for node in ast.walk(tree) if isinstance(node, ast.Import | ast.ImportFrom)]


def test_the_stage2_protocol_preloads_the_default_number_of_positives():
    """YAML cannot import the constant: the protocol file's value is checked against it, and the
    run directories name that number ``stage2``."""
    stage2 = OmegaConf.load(RECIPES / "protocol" / "stage2.yaml")
    assert stage2.train.preload_positives == defaults.STAGE2_POSITIVES
    assert protocol_name(defaults.STAGE2_POSITIVES) == "stage2"


def test_the_benchmarks_config_and_its_dataset_spec_share_their_defaults():
    """``dataset.*`` and ``env.*``'s render settings default to what ``DatasetSpec`` does, so a
    spec built in code collects the dataset the recipe's default config collects."""
    spec = DatasetSpec("drawer-open")
    for config in (DatasetConfig(), EnvParams()):
        shared = {field.name for field in dataclasses.fields(config)} & {
            field.name for field in dataclasses.fields(spec)} - {"task", "seed"}
        assert shared, config
        assert {name: getattr(config, name) for name in shared} == {
            name: getattr(spec, name) for name in shared}
