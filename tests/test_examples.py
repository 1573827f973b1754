"""The scripts in examples/ run, on tiny settings (the state encoder, short episodes), so the
guides that include them cannot drift from the code."""

import runpy
import sys
from pathlib import Path

import pytest
import sac_temporal
import torch
from helpers import synthetic_episode
from hydra import compose, initialize_config_dir
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.objectives import DirectionalLoss, finetuning_losses
from temporal_torchrl.rewards import (
    POSITIONAL,
    TemporalReward,
    reward_from_config,
    unregister_reward,
)
from temporal_torchrl.training import RewardHeadTrainer

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


def test_own_directional_reward_with_its_options_in_the_recipe(tmp_path, example_reward_module):
    """The extending guide's command: ``reward.modules=[examples/my_directional_reward.py]
    reward.directional=d_sharp +reward.options.sharpness=4 +reward.options.margin=0.2``."""
    with initialize_config_dir(config_dir=str(ROOT / "recipes"), version_base=None):
        cfg = compose("config", overrides=[
            *TINY_RUN, f"reward.modules=[{example_reward_module}]",
            "reward.directional=d_sharp", "+reward.options.sharpness=4",
            "+reward.options.margin=0.2", f"output_dir={tmp_path / 'run'}"])
    summary = sac_temporal.train(cfg)
    assert summary["episodes"] == 3
    saved = summary["config"]["reward"]
    assert saved["directional"] == "d_sharp"
    assert saved["options"] == {"sharpness": 4, "margin": 0.2}
    # The run's saved config rebuilds the reward with its options, finetuned by its own loss.
    reward = reward_from_config(summary["config"], torch.randn(16), torch.randn(16))
    assert reward.options == {"sharpness": 4.0, "margin": 0.2}
    losses = finetuning_losses(reward, torch.randn(16), stage=1)
    assert [type(loss).__name__ for loss in losses] == ["PositionalRankingLoss",
                                                        "MarginDirectionalLoss"]


def test_own_loss_of_the_directional_example_by_hand(example_reward_module):
    """d_sharp's MarginDirectionalLoss on a stage-2 batch: the hinge of each group, written
    out with the reward function and the options the reward was given."""
    namespace = runpy.run_path(str(example_reward_module))
    gen = torch.Generator().manual_seed(3)
    dim, count = 6, 5
    reward = TemporalReward(dim, torch.randn(dim, generator=gen), torch.randn(dim, generator=gen),
                            positional=None, directional="d_sharp",
                            options={"sharpness": 3, "margin": 0.25})
    goal = torch.randn(dim, generator=gen)
    loss, = finetuning_losses(reward, goal, stage=2)
    assert isinstance(loss, namespace["MarginDirectionalLoss"])

    def states() -> TensorDict:
        s_t, s_tk, s_0 = (torch.randn(count, dim, generator=gen) for _ in range(3))
        return TensorDict({"embedding": s_t, "previous_embedding": s_tk,
                           "initial_embedding": s_0}, [count])

    negative, positive = states(), states()
    heads, g, b = reward.directional_heads, reward.goal_embedding, reward.baseline_embedding

    def r(s, s_prev, position):
        return namespace["sharpened_d3"](heads, s, s_prev=s_prev, g=g, b=b, sharpness=3.0,
                                         position=position)

    n_t, n_tk = negative["embedding"], negative["previous_embedding"]
    expected_negative = torch.relu(0.25 + r(n_t, n_tk, None)
                                   - r(goal.expand_as(n_t), n_t, n_t)).mean()
    p_t, p_tk = positive["embedding"], positive["previous_embedding"]
    expected_positive = torch.relu(0.25 + r(p_tk, p_t, p_t) - r(p_t, p_tk, None)).mean()
    out = loss(TensorDict({"negative": negative, "positive": positive}, [count]))
    assert out["loss_negative"].item() == pytest.approx(expected_negative.item(), abs=1e-6)
    assert out["loss_positive"].item() == pytest.approx(expected_positive.item(), abs=1e-6)
    out["loss_directional"].backward()
    assert all(parameter.grad is not None for parameter in loss.parameters())


def test_a_built_in_loss_plus_one_term_through_terms(example_reward_module):
    """The extending guide's DecayedDirectionalLoss (d3_decay): the built-in directional loss's
    terms, unchanged, plus ``loss_decay``, all summed into ``loss_directional``; one trainer
    update changes the heads and reports the new term."""
    namespace = runpy.run_path(str(example_reward_module))
    torch.manual_seed(4)
    dim = 4
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional=None,
                            directional="d3_decay", k=2, options={"decay": 0.5})
    buffer = EpisodeReplayBuffer(capacity=100, reward=reward, gap=3)
    for success in (None, torch.arange(20) >= 12):
        buffer.extend(episode_rows(synthetic_episode(torch.randn(21, dim), success)))
    goal = torch.randn(dim)
    trainer = RewardHeadTrainer(reward, goal, buffer.finetuning, batch_size=8)
    loss, = trainer.losses
    assert isinstance(loss, namespace["DecayedDirectionalLoss"]) and trainer.stage == 2
    heads = [parameter.detach().clone() for parameter in reward.directional_heads.parameters()]
    batch = buffer.finetuning.sample(8)
    out, built_in = loss(batch), DirectionalLoss(reward, goal, stage=2)(batch)
    for name in ("loss_negative", "loss_positive"):
        assert torch.equal(out[name], built_in[name])
    squares = torch.stack([parameter.square().sum() for parameter in heads]).sum()
    torch.testing.assert_close(out["loss_decay"], 0.5 * squares)
    torch.testing.assert_close(out["loss_directional"],
                               built_in["loss_directional"] + out["loss_decay"])
    assert int(out["summed_parts"]) == 3
    metrics = trainer.update()
    assert metrics["loss_decay"] > 0
    assert not all(torch.equal(before, after) for before, after in
                   zip(heads, reward.directional_heads.parameters(), strict=True))
