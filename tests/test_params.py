"""The components' parameter objects (temporal_torchrl.params): the schemas nest them, the
library's constructors take them, an object built in code is checked as a config key is, and
the history's k and window each have one route."""

import dataclasses

import pytest
import torch
from helpers import config, make_episode
from omegaconf import OmegaConf

from temporal_torchrl.configs import RewardQualityConfig
from temporal_torchrl.configs.recipe import EnvConfig, RecipeConfig, TrainConfig
from temporal_torchrl.configs.reward_quality import DatasetConfig, RewardQualityEnvConfig
from temporal_torchrl.configs.rules import validate_reward_quality_config
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.envs import collect_expert_episodes, make_env, make_temporal_env
from temporal_torchrl.fields import CONSTRAINT
from temporal_torchrl.params import (
    DatasetParams,
    EnvParams,
    EvalParams,
    RelayParams,
    env_params,
)
from temporal_torchrl.reward_quality import DatasetSpec
from temporal_torchrl.rewards import TemporalReward
from temporal_torchrl.training.evaluation import PolicyEvaluation


@pytest.mark.parametrize(("params", "section"), [
    (EnvParams, EnvConfig), (EnvParams, RewardQualityEnvConfig), (DatasetParams, DatasetConfig),
])
def test_the_schemas_nest_the_parameter_objects(params, section):
    """A schema section is its parameter object (a subclass), so a key's type, default and
    range are the object's field, written once."""
    assert issubclass(section, params)
    for spec in dataclasses.fields(params):
        nested = next(field for field in dataclasses.fields(section) if field.name == spec.name)
        assert nested.metadata == spec.metadata, spec.name
    assert RecipeConfig().eval == EvalParams()


def test_the_relay_keys_take_their_defaults_and_ranges_from_relay_params():
    """``train.relay_*`` keep their names on the command line; their defaults and ranges are
    ``RelayParams``' fields."""
    train = {field.name: field for field in dataclasses.fields(TrainConfig)}
    for spec in dataclasses.fields(RelayParams):
        key = train[f"relay_{spec.name}"]
        assert key.metadata[CONSTRAINT] == spec.metadata[CONSTRAINT]
        assert getattr(TrainConfig(), key.name) == getattr(RelayParams(), spec.name)


def test_a_composed_config_hands_the_library_its_parameter_objects(tmp_path):
    cfg = config(tmp_path, "env.task=door-open", "env.seed=3", "env.goal=random",
                 "eval.episodes=4", "train.relay_noise=0.5")
    env = EnvParams.from_section(cfg.env)
    assert env == EnvParams("door-open", seed=3, max_episode_steps=20, goal="random")
    assert EvalParams.from_section(cfg.eval) == EvalParams(episodes=4)


@pytest.mark.parametrize(("build", "message"), [
    (lambda: EnvParams(image_size=0), r"EnvParams: image_size=0; expected an integer >= 1"),
    (lambda: EnvParams(goal="moving"), r"EnvParams: goal='moving'; expected one of fixed, rand"),
    (lambda: EnvParams(fast_render=1), r"EnvParams: fast_render=1; expected true or false"),
    (lambda: EnvParams(seed=1.5), r"EnvParams: seed=1.5; expected an integer >= 0"),
    (lambda: EvalParams(episodes=True), r"EvalParams: episodes=True; expected an integer >= 1"),
    (lambda: RelayParams(periods=[]), r"periods=\[\]; expected a non-empty list, each item an "
                                      r"integer >= 1"),
    (lambda: RelayParams(noise=-0.1), r"RelayParams: noise=-0.1; expected a number >= 0"),
    (lambda: DatasetParams(expert_episodes=1), r"expert_episodes=1; expected an integer >= 2"),
    (lambda: EnvParams().replace(max_episode_steps=0), r"max_episode_steps=0"),
])
def test_an_object_built_in_code_is_checked_as_a_config_key_is(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_env_params_keeps_the_fields_a_none_keyword_leaves_unset():
    base = EnvParams("push", seed=2, image_size=48)
    assert env_params(base) is not base and env_params(base) == base
    assert env_params(base, None, image_size=None, camera="corner") == EnvParams(
        "push", seed=2, image_size=48, camera="corner")
    assert env_params("push") == EnvParams("push")


def test_make_env_takes_the_parameter_object_or_the_same_settings_as_keywords():
    """One route into the env: an ``EnvParams`` gives the layout, length and frames that the
    same values as keywords give; the frames default to EnvParams' 64 px."""
    params = EnvParams("drawer-open", seed=4, max_episode_steps=3, image_size=32)
    torch.manual_seed(0)
    by_object = make_env(params, render=True).rollout(3)
    torch.manual_seed(0)
    by_keywords = make_env("drawer-open", 4, render=True, image_size=32,
                           max_episode_steps=3).rollout(3)
    assert torch.equal(by_object["next", "pixels"], by_keywords["next", "pixels"])
    assert torch.equal(by_object["observation"], by_keywords["observation"])
    assert by_object["next", "pixels"].shape == (3, 32, 32, 3)
    default = make_env(EnvParams("drawer-open", max_episode_steps=1), render=True).rollout(1)
    assert default["next", "pixels"].shape[1:3] == (EnvParams().image_size,) * 2


def test_the_temporal_env_the_experts_and_the_evaluation_take_one_env_params():
    params = EnvParams("reach", seed=1, max_episode_steps=8)
    env = make_temporal_env(params)
    assert env.max_episode_steps == 8 and env.seed == 1
    expert, = collect_expert_episodes(params, num_episodes=1, steps_after_success=None)
    assert len(expert) == 8
    evaluation = PolicyEvaluation(params.replace(goal="random"), episodes=1)
    assert evaluation.env.goal == "random" and evaluation.env.max_episode_steps == 8


def test_the_dataset_spec_is_the_env_and_the_dataset_parameters():
    spec = DatasetSpec.of(EnvParams("push", seed=2, image_size=48), DatasetParams(
        expert_episodes=4))
    assert (spec.task, spec.seed, spec.image_size, spec.expert_episodes) == ("push", 2, 48, 4)
    assert spec.env == EnvParams("push", seed=2, image_size=48)
    assert DatasetSpec("push") == DatasetSpec.of(EnvParams("push"), DatasetParams())
    with pytest.raises(ValueError, match="goal='random'.*seed's layout"):
        DatasetSpec.of(EnvParams("push", goal="random"), DatasetParams())
    with pytest.raises(ValueError, match="DatasetSpec: image_size=0; expected an integer >= 1"):
        DatasetSpec("push", image_size=0)


def test_the_reward_quality_recipe_refuses_random_goals():
    cfg = OmegaConf.merge(OmegaConf.structured(RewardQualityConfig), {"env": {"goal": "random"}})
    with pytest.raises(ValueError, match=r"env.goal='random' is invalid: expected fixed"):
        validate_reward_quality_config(cfg)


def test_the_replay_takes_the_window_from_the_reward_and_refuses_another():
    """The window has the route k has: the reward's, a different one refused naming both."""
    dim = 4
    reward = TemporalReward(dim, torch.randn(dim), torch.randn(dim), positional="furl",
                            directional="d_sequence", options={"window": 4})
    buffer = EpisodeReplayBuffer(capacity=60, reward=reward)
    assert buffer.window_length == 4
    assert EpisodeReplayBuffer(capacity=60, reward=reward, window_length=4).window_length == 4
    with pytest.raises(ValueError, match=r"window_length=8 but the reward's window_length is 4"):
        EpisodeReplayBuffer(capacity=60, reward=reward, window_length=8)
    plain = TemporalReward(dim, torch.randn(dim), torch.randn(dim))
    with pytest.raises(ValueError, match=r"window_length=4 but the reward's window_length is "
                                         r"None"):
        EpisodeReplayBuffer(capacity=60, reward=plain, window_length=4)
    buffer.extend(episode_rows(make_episode(0, 12, dim=dim), embedding_dtype=torch.float32))
    assert buffer.sample(4)["next", "embedding_window"].shape[-2] == 4
