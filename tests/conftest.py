"""Shared test settings: headless rendering, a deterministic torch and the recipes' config
schemas in Hydra's ConfigStore for any test that composes a recipe's config (the recipes are
importable through pytest's ``pythonpath``, see pyproject.toml)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("WANDB_MODE", "offline")

import pytest  # noqa: E402
import torch  # noqa: E402

import temporal_torchrl.configs  # noqa: E402, F401 (registers the schemas)


@pytest.fixture
def one_torch_thread():
    """Tiny networks run fastest on one thread; two threads spin against each other on a busy
    2-core machine (10x slower). Restored afterwards for the other test files."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(autouse=True)
def _seed_torch():
    torch.manual_seed(0)

