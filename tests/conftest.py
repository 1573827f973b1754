"""Shared test settings: headless rendering, one torch thread, a deterministic torch, the
slowest tests first, and the recipes' config schemas in Hydra's ConfigStore for any test that
composes a recipe's config (the recipes are importable through pytest's ``pythonpath``, see
pyproject.toml)."""

import os
import sys
from collections.abc import Iterator
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("WANDB_MODE", "offline")
# The suite runs one pytest worker per core (``-n auto``) and its networks are tiny: a second
# torch thread per process only spins against the other worker (10x slower on a busy 2-core
# machine; 12% of the whole suite's CPU, measured). Set before torch is imported, so that the
# recipes the tests start as subprocesses inherit it too.
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402
import torch  # noqa: E402

import temporal_torchrl.configs  # noqa: E402, F401 (registers the schemas)

torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))


@pytest.fixture(autouse=True)
def _seed_torch():
    torch.manual_seed(0)


@pytest.fixture
def example_reward_module() -> Iterator[Path]:
    """examples/my_directional_reward.py, which registers d_sharp and d3_decay when a test loads
    it (by the recipe's ``reward.modules`` or by hand): both unregistered afterwards and the module
    forgotten, so the registry is left as it was found."""
    from temporal_torchrl.rewards import DIRECTIONAL, unregister_reward
    loaded = set(sys.modules)
    yield Path(__file__).resolve().parents[1] / "examples" / "my_directional_reward.py"
    for name in ("d_sharp", "d3_decay"):
        if name in DIRECTIONAL:
            unregister_reward(name)
    for name in set(sys.modules) - loaded:
        if name.startswith("reward_module_"):
            del sys.modules[name]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The Slurm test, then the other slow ones, then the rest (each group in collection order):
    with ``--maxschedchunk 1`` (pyproject.toml) each worker takes one test at a time, so the
    workers end together instead of one of them finishing a minute-long test alone."""
    items.sort(key=lambda item: (item.get_closest_marker("slurm") is None,
                                 item.get_closest_marker("slow") is None))
