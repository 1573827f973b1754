"""The README's composition examples run as written, in order (offline: shipped encoder,
rendering), and give the rewards of the thesis's combination."""

import re
from pathlib import Path

import torch

README = Path(__file__).resolve().parents[1] / "README.md"


def combined(rollout) -> torch.Tensor:
    """r = r_task + rho (r_P + lambda r_D) with the README's rho 1.0 and lambda 4.0."""
    return (rollout["next", "task_reward"] + 1.0 * (
        rollout["next", "positional_reward"] + 4.0 * rollout["next", "directional_reward"]))


def test_readme_composition_examples_run():
    section = README.read_text().split("## Composing the pieces")[1].split("\n## ")[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)
    assert len(blocks) >= 3  # the encoders subsection follows with its own
    namespace: dict = {}
    exec(compile(blocks[0], str(README), "exec"), namespace)
    rollout = namespace["rollout"]
    assert rollout.batch_size == (10,)
    assert "pixels" not in rollout.keys()  # dropped after embedding
    assert rollout["next", "embedding"].shape == (10, namespace["encoder"].dim)
    assert (rollout["next", "reward"] - combined(rollout)).abs().max() < 1e-5

    exec(compile(blocks[1], str(README), "exec"), namespace)  # the same env, by hand
    by_hand = namespace["env"].rollout(10)
    assert (by_hand["next", "reward"] - combined(by_hand)).abs().max() < 1e-5
    assert set(by_hand.keys(True)) == set(rollout.keys(True))

    exec(compile(blocks[2], str(README), "exec"), namespace)
    batch, metrics = namespace["batch"], namespace["metrics"]
    assert batch.batch_size == (256,) and batch["step"].max() <= 9
    assert set(metrics.keys()) >= {"loss_positional", "loss_directional", "stage"}
