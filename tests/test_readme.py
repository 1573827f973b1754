"""The README's composition example runs as written (offline: shipped encoder, rendering)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_composition_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.DOTALL)
    example = next(block for block in blocks if "append_transform" in block)
    namespace: dict = {}
    exec(compile(example, str(README), "exec"), namespace)
    rollout = namespace["rollout"]
    assert rollout.batch_size == (10,)
    assert "pixels" not in rollout.keys()  # dropped after embedding
    assert rollout["next", "embedding"].shape == (10, namespace["encoder"].dim)
    expected = (rollout["next", "task_reward"]
                + 1.0 * (rollout["next", "positional_reward"]
                         + 4.0 * rollout["next", "directional_reward"]))
    assert (rollout["next", "reward"] - expected).abs().max() < 1e-5
