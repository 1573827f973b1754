"""The README is a landing page whose commands run as written: install, the main run and the
test command in its first screen (the test command the one CI runs), its composition example
executed (offline: shipped encoder, rendering) with the rewards of the thesis's combination,
its links pointing at files that exist, and its docs command the one CI builds with."""

import re
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
CI = ROOT / ".ci" / "run"

TRAIN = ("python3 -m venv .venv && .venv/bin/pip install -e . && "
         ".venv/bin/python recipes/sac_temporal.py")
TEST = ("python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && "
        ".venv/bin/python -m pytest -q")
DOCS = ".venv/bin/python -m sphinx -W --keep-going -n -b html docs docs/_build/html"


def combined(rollout) -> torch.Tensor:
    """r = r_task + rho (r_P + lambda r_D) with the README's rho 1.0 and lambda 4.0."""
    return (rollout["next", "task_reward"] + 1.0 * (
        rollout["next", "positional_reward"] + 4.0 * rollout["next", "directional_reward"]))


def test_first_screen_has_install_the_main_run_and_the_tests():
    first_screen = "\n".join(README.read_text().splitlines()[:35])
    assert TRAIN in first_screen
    assert TEST in first_screen


def test_ci_runs_the_readme_test_and_docs_commands():
    """CI's commands are the README's, with a quiet pip and the slowest tests listed."""
    ci = CI.read_text()
    ci_test = next(line for line in ci.splitlines() if "pytest" in line)
    assert ci_test.replace("pip install -q ", "pip install ").replace(" --durations=15", "") == TEST
    assert DOCS in ci and DOCS in README.read_text()


def test_readme_is_a_landing_page():
    assert len(README.read_text().split()) <= 1500


def test_readme_links_point_at_files():
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README.read_text())
    local = [link for link in links if not re.match(r"[a-z]+://", link)]
    assert len(local) >= 10
    missing = [link for link in local if not (ROOT / link).exists()]
    assert not missing, missing


def test_readme_composition_example_runs():
    section = README.read_text().split("## Composing the pieces")[1].split("\n## ")[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], str(README), "exec"), namespace)
    rollout = namespace["rollout"]
    assert rollout.batch_size == (10,)
    assert "pixels" not in rollout.keys()  # dropped after embedding
    assert rollout["next", "embedding"].shape == (10, namespace["encoder"].dim)
    assert (rollout["next", "reward"] - combined(rollout)).abs().max() < 1e-5
