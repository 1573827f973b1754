"""The scripts in examples/ run, on tiny settings (the state encoder, short episodes), so the
guides that include them cannot drift from the code."""

import runpy
import sys
from pathlib import Path

import pytest
import sac_temporal
from hydra import compose, initialize_config_dir

from temporal_torchrl.rewards import POSITIONAL, unregister_reward

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


# The recipe on a tiny run (as tests/test_recipe.py): 20-step episodes, small networks.
TINY_RUN = [
    "env.max_episode_steps=20", "train.episodes=3", "train.random_steps=10",
    "encoder.name=state", "+encoder.options.dim=16", "sac.batch_size=16",
    "sac.hidden_sizes=[32,32]", "reward.batch_size=16", "reward.gap=3", "logger.backend=none",
    "train.progress=false", "train.threads=1",
]


def example_main(name: str):
    """The ``main`` of examples/<name>, loaded without running it."""
    return runpy.run_path(str(EXAMPLES / name), run_name=f"example_{Path(name).stem}")["main"]


@pytest.fixture
def no_p5():
    """examples/my_rewards.py registers "p5": leave the registry as it was found."""
    loaded = set(sys.modules)
    yield
    if "p5" in POSITIONAL:
        unregister_reward("p5")
    for name in set(sys.modules) - loaded:
        if name.startswith("reward_module_"):
            del sys.modules[name]


def test_compose_env(capsys):
    example_main("compose_env.py")(["--encoder", "state", "--steps", "5"])
    out = capsys.readouterr().out
    assert "make_temporal_env: 5 steps" in out and "by hand: 5 steps" in out


def test_replay_and_trainer(capsys):
    example_main("replay_and_trainer.py")(
        ["--encoder", "state", "--episodes", "2", "--steps", "20", "--updates", "2"])
    out = capsys.readouterr().out
    assert "a SAC batch of 256" in out and "loss_positional" in out and "loss_directional" in out


def test_own_reward_in_an_env(capsys, no_p5):
    example_main("my_rewards.py")(["--encoder", "state", "--steps", "5"])
    assert "p5 along 5 random steps" in capsys.readouterr().out


def test_own_reward_in_the_recipe(tmp_path, no_p5):
    """The guide's command: ``reward.modules=[examples/my_rewards.py] reward.positional=p5``."""
    with initialize_config_dir(config_dir=str(ROOT / "recipes"), version_base=None):
        cfg = compose("config", overrides=[
            *TINY_RUN, f"reward.modules=[{EXAMPLES / 'my_rewards.py'}]", "reward.positional=p5",
            f"output_dir={tmp_path / 'run'}"])
    summary = sac_temporal.train(cfg)
    assert summary["episodes"] == 3
    assert summary["config"]["reward"]["positional"] == "p5"


def test_own_encoder(capsys):
    example_main("own_encoder.py")(["--steps", "5"])
    assert "bag_of_words_state: embedding (5, 64)" in capsys.readouterr().out
