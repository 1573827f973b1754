"""Shared test settings: headless rendering and a deterministic torch (the recipes are
importable through pytest's ``pythonpath``, see pyproject.toml)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("WANDB_MODE", "offline")

import pytest  # noqa: E402
import torch  # noqa: E402


@pytest.fixture(autouse=True)
def _seed_torch():
    torch.manual_seed(0)
