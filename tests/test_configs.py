"""The recipes' config schemas (temporal_torchrl.configs): they agree with the YAML files, Hydra
refuses a wrong type naming the key, the declared ranges and the rules refuse a bad value naming
the key, and a resumed config is typed and checked like a new one."""

import dataclasses
import inspect
import itertools
import json
import re

import pytest
import torch
from helpers import RECIPES, error_chain
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from temporal_torchrl.configs import RecipeConfig, RewardQualityConfig
from temporal_torchrl.configs.rules import (
    Devices,
    validate_recipe_config,
    validate_reward_quality_config,
)
from temporal_torchrl.runs import resumed_config


def composed(config_name: str, *overrides: str):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose(config_name, overrides=list(overrides))


@pytest.mark.parametrize(("yaml_file", "schema"), [
    ("config.yaml", RecipeConfig), ("evaluate_rewards.yaml", RewardQualityConfig)])
def test_every_setting_has_one_home_the_schema(yaml_file, schema):
    """The YAML holds the composition and Hydra's settings only: every key's default is stated
    in the schema, and there each key says what it means in a ``#:`` comment (a group, by its
    class's docstring)."""
    written = OmegaConf.to_container(OmegaConf.load(RECIPES / yaml_file))
    assert set(written) == {"defaults", "hydra"}
    module = inspect.getmodule(schema)
    classes = [cls for _, cls in inspect.getmembers(module, dataclasses.is_dataclass)
               if cls.__module__ == module.__name__]
    undocumented = []
    for cls in classes:
        assert cls.__doc__, cls.__name__
        groups = {field.name for field in dataclasses.fields(cls)
                  if dataclasses.is_dataclass(field.default_factory)}
        lines = inspect.getsource(cls).splitlines()
        for before, line in itertools.pairwise(lines):
            key = re.match(r" {4}(\w+): ", line)
            if key and key[1] not in groups and not before.strip().startswith("#:"):
                undocumented.append(f"{cls.__name__}.{key[1]}")
    assert undocumented == []


def test_defaults_presets_and_protocols_pass_the_rules():
    validate_reward_quality_config(composed("evaluate_rewards"))
    for preset in sorted(path.stem for path in (RECIPES / "preset").glob("*.yaml")):
        for protocol in ("stage1", "stage2"):
            cfg = validate_recipe_config(composed("config", f"preset={preset}",
                                                  f"protocol={protocol}"))
            assert OmegaConf.get_type(cfg) is RecipeConfig


@pytest.mark.parametrize(("config_name", "override", "message"), [
    ("config", "train.episodes=many", "Value 'many' of type 'str' could not be converted to "
     "Integer\n    full_key: train.episodes"),
    ("config", "reward.rho=1.5.2", "full_key: reward.rho"),
    ("config", "train.relay=maybe", "Value 'maybe' is not a valid bool (type str)\n"
     "    full_key: train.relay"),
    ("config", "sac.hidden_sizes=256", "full_key: sac.hidden_sizes"),
    ("config", "encoder=state", "str is not a subclass of EncoderConfig. value: state\n"
     "    full_key: encoder"),
    ("config", "train.epsiodes=5", "Could not override 'train.epsiodes'"),
    ("evaluate_rewards", "finetune.updates=1e3", "full_key: finetune.updates"),
])
def test_hydra_refuses_a_wrong_type_naming_the_key(config_name, override, message):
    with pytest.raises(ConfigCompositionException, match=re.escape(override)) as error:
        composed(config_name, override)
    assert message in error_chain(error.value)


PLUS_APPLIES = "'+' adds keys only under reward.options and encoder.options"


@pytest.mark.parametrize(("override", "key", "suggestion"), [
    ("+train.epsiodes=3", "train.epsiodes", "Did you mean train.episodes?"),
    ("+sac.foo=1", "sac.foo", None),
    ("+env.camra=x", "env.camra", "Did you mean env.camera?"),
    ("+eval.seed=3", "eval.seed", None),
    ("+encoder.dims=8", "encoder.dims", None),
    ("+reward.lambda=2", "reward.lambda", "Did you mean reward.lambda_?"),
    ("+replay_buffer.capacty=9", "replay_buffer.capacty", "Did you mean replay_buffer.capacity?"),
    ("+compile.enable=true", "compile.enable", "Did you mean compile.enabled?"),
    ("+logger.projekt=x", "logger.projekt", "Did you mean logger.project?"),
    ("+seed=1", "seed", None),
])
def test_a_key_nothing_reads_is_refused_naming_it(override, key, suggestion):
    cfg = composed("config", override)  # Hydra adds it: '+' is how its message says to
    with pytest.raises(ValueError) as error:
        validate_recipe_config(cfg)
    message = str(error.value)
    assert message.startswith(f"config key {key!r} is not declared ")
    assert PLUS_APPLIES in message
    assert (suggestion in message) if suggestion else "Did you mean" not in message


def test_the_reward_quality_recipe_refuses_a_key_nothing_reads():
    cfg = composed("evaluate_rewards", "+dataset.expert_episode=3")
    with pytest.raises(ValueError, match=r"config key 'dataset\.expert_episode' is not declared in "
                                         r"section 'dataset' \(DatasetConfig\).*Did you mean "
                                         r"dataset\.expert_episodes\?"):
        validate_reward_quality_config(cfg)


def test_open_groups_and_hydras_keys_are_not_refused():
    cfg = validate_recipe_config(composed("config", "encoder.name=state", "+encoder.options.dim=8"))
    assert cfg.encoder.options.dim == 8
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        with_hydra = compose("config", return_hydra_config=True)
    validate_recipe_config(with_hydra)


@pytest.mark.parametrize("study", sorted(path.stem for path in (RECIPES / "study").glob("*.yaml")))
def test_every_study_file_declares_only_keys_the_recipe_reads(study):
    validate_recipe_config(composed("config", f"+study={study}", "env.task=drawer-open"))


SCALE_KEYS = ("encoder", "env", "compile", "episodes", "random_steps")


PRESETS = sorted(path.stem for path in (RECIPES / "preset").glob("*.yaml"))


@pytest.mark.parametrize("preset", PRESETS)
def test_a_preset_states_its_reward_and_leaves_the_scale_to_the_scale_group(preset):
    written = OmegaConf.to_container(OmegaConf.load(RECIPES / "preset" / f"{preset}.yaml"))
    stated = {f"{key}.{sub}" if isinstance(value, dict) else key: None
              for key, value in written.items() if key != "defaults"
              for sub in (value if isinstance(value, dict) else [None])}
    assert not [key for key in stated if any(part in key.split(".") for part in SCALE_KEYS)]
    thesis = composed("config", f"preset={preset}")
    cpu = composed("config", f"preset={preset}", "scale=cpu", "env.task=door-open")
    if preset != "none":  # the quick default: the schema's scale
        assert (thesis.encoder.name, thesis.env.image_size, thesis.train.episodes,
                thesis.train.random_steps) == ("liv", 256, 1000, 10_000)
    assert (cpu.encoder.name, cpu.env.image_size, cpu.train.episodes, cpu.train.random_steps,
            cpu.compile.enabled) == ("metaworld_small", 64, 400, 10_000, True)
    assert cpu.reward == thesis.reward  # the scale changes no reward key


@pytest.mark.parametrize("preset", ["sac", "furl_rho1", "none"])
def test_the_cpu_study_is_preset_protocol_and_scale(preset):
    overrides = (f"preset={preset}", "protocol=stage2", "env.task=push")
    study = OmegaConf.to_container(composed("config", "+study=table_5_12_cpu", *overrides))
    assert study == OmegaConf.to_container(composed("config", "scale=cpu", *overrides))


@pytest.mark.parametrize(("override", "message"), [
    ("train.episodes=0", "config train.episodes=0 is invalid: expected an integer >= 1. Fix it on "
     "the command line, e.g. train.episodes=<value>."),
    ("sac.gamma=1.5", "config sac.gamma=1.5 is invalid: expected a number in (0, 1]."),
    ("reward.alpha=-0.1", "config reward.alpha=-0.1 is invalid: expected a number in [0, 1]."),
    ("train.threads=0", "config train.threads=0 is invalid: expected an integer >= 1, or null."),
    ("sac.hidden_sizes=[256,0]", "config sac.hidden_sizes=[256, 0] is invalid: expected a "
     "non-empty list of integers >= 1, e.g. [256,256]."),
    ("train.relay_periods=[]", "expected a non-empty list of integers >= 1, e.g. "
     "[50,100,150,200]"),
    ("logger.backend=tensorboard", "config logger.backend='tensorboard' is invalid: expected one "
     "of wandb, csv, none."),
    ("compile.mode=fastest", "expected one of default, reduce-overhead, max-autotune, "
     "max-autotune-no-cudagraphs, or null."),
    ("replay_buffer.capacity=100", "config replay_buffer.capacity=100 is invalid: expected null "
     "(the whole run) or an integer >= 501"),
])
def test_a_value_out_of_range_is_refused_naming_the_key(override, message):
    cfg = composed("config", override)  # the type is right: Hydra composes it
    with pytest.raises(ValueError) as error:
        validate_recipe_config(cfg)
    assert message in str(error.value)


def test_devices_are_resolved_once_and_the_config_keeps_their_names():
    """``auto`` for the encoder and the replay is the train device, resolved in one place for
    every factory; the validated config (config.json, the run directory, the resume checks)
    keeps the names as given. A device torch cannot use is refused naming its key."""
    cfg = validate_recipe_config(composed("config", "train.device=cpu",
                                          "replay_buffer.device=auto"))
    assert Devices.of(cfg) == Devices(*[torch.device("cpu")] * 3)
    assert (cfg.encoder.device, cfg.replay_buffer.device) == ("auto", "auto")
    with pytest.raises(ValueError, match=r"config replay_buffer\.device='tpu' is invalid"):
        Devices.of(composed("config", "replay_buffer.device=tpu"))


def test_the_reward_quality_ranges_are_its_own():
    with pytest.raises(ValueError, match=r"dataset\.held_out_fraction=1\.0 is invalid: expected "
                                         r"a number in \(0, 1\)"):
        validate_reward_quality_config(composed("evaluate_rewards", "dataset.held_out_fraction=1"))
    with pytest.raises(ValueError, match=r"finetune\.stage=3 is invalid: expected one of 1, 2"):
        validate_reward_quality_config(composed("evaluate_rewards", "finetune.stage=3"))


def test_a_config_built_in_code_is_typed_by_the_schema():
    with pytest.raises(ValueError, match=r"config reward\.rho is invalid: Value 'abc' of type "
                                         r"'str' could not be converted to Float"):
        validate_recipe_config(OmegaConf.create({"reward": {"rho": "abc"}}))
    with pytest.raises(ValueError, match=r"config key 'train\.epsiodes' is not declared in "
                                         r"section 'train' \(TrainConfig\)"):
        validate_recipe_config(OmegaConf.create({"train": {"epsiodes": 5}}))
    cfg = validate_recipe_config(OmegaConf.create({"train": {"utd_ratio": "0.5"}}))
    assert cfg.train.utd_ratio == 0.5 and cfg.env.task == "drawer-open"  # the rest: defaults


def test_an_older_run_resumes_with_the_current_defaults_for_its_missing_keys(tmp_path):
    saved = OmegaConf.to_container(composed("config", "reward.rho=0.5"), resolve=True)
    del saved["reward"]["certainty_scaling"], saved["train"]["relay_threshold"]
    saved["train"]["utd_ratio"] = "2"  # a hand-edited config.json: typed on resume
    (tmp_path / "config.json").write_text(json.dumps(saved))
    current = composed("config", "resume=true", f"output_dir={tmp_path}")
    cfg = validate_recipe_config(resumed_config(current, tmp_path, given_keys={"resume"}))
    assert OmegaConf.get_type(cfg) is RecipeConfig
    assert (cfg.reward.rho, cfg.reward.certainty_scaling, cfg.train.relay_threshold) == (
        0.5, False, 2500)
    assert cfg.train.utd_ratio == 2.0 and cfg.resume

    saved["reward"]["k"] = 0
    (tmp_path / "config.json").write_text(json.dumps(saved))
    with pytest.raises(ValueError, match=r"config reward\.k=0 is invalid"):
        validate_recipe_config(resumed_config(current, tmp_path, given_keys={"resume"}))


def test_reward_options_are_those_the_configured_rewards_declare(example_reward_module):
    with pytest.raises(ValueError, match=r"config reward\.options\.sharpness=4 is invalid: "
                                         r"expected an option of furl or d3: they declare none"):
        validate_recipe_config(composed("config", "+reward.options.sharpness=4"))
    own = [f"reward.modules=[{example_reward_module}]", "reward.directional=d_sharp"]
    cfg = validate_recipe_config(composed("config", *own, "+reward.options.sharpness=4"))
    assert OmegaConf.to_container(cfg.reward.options) == {"sharpness": 4}
    with pytest.raises(ValueError, match=r"config reward\.options\.margin='wide' is invalid: "
                                         r"expected a float like d_sharp's default 0\.1"):
        validate_recipe_config(composed("config", *own, "+reward.options.margin=wide"))
    # The offline benchmark: an option of any listed variant (each variant gets its own only).
    listed = [f"reward.modules=[{example_reward_module}]", "reward.positional=none",
              "reward.directional=[d3,d_sharp]"]
    validate_reward_quality_config(composed("evaluate_rewards", *listed,
                                            "+reward.options.margin=0.3"))
    with pytest.raises(ValueError, match=r"reward\.options\.temperature=1 is invalid: expected "
                                         r"an option of d3 or d_sharp: sharpness, margin"):
        validate_reward_quality_config(composed("evaluate_rewards", *listed,
                                                "+reward.options.temperature=1"))


def validated_with_warnings(validate, config_name: str, *overrides: str):
    """``validate`` of the composed config, and the messages of the FutureWarnings it gave."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cfg = validate(composed(config_name, *overrides))
    return cfg, [str(warning.message) for warning in caught
                 if warning.category is FutureWarning]


def test_the_built_in_options_are_set_under_reward_options_and_the_old_keys_still_work():
    """d_sequence's window and d_certainty's certainty estimate are set as any reward's options
    are (``+reward.options.window=12``). The keys that set them before (``reward.window``,
    ``reward.certainty_bandwidth``, ``reward.certainty_prior``) still work for one release:
    moved into ``reward.options`` with a FutureWarning naming the new key, silently ignored at
    their old default (what every saved config holds), refused when they disagree with the new
    key, and refused, naming where they came from, for a reward that has no such option."""
    from temporal_torchrl.rewards import reward_from_config

    sequence = "reward.directional=d_sequence"
    new, warned = validated_with_warnings(validate_recipe_config, "config", sequence,
                                          "+reward.options.window=12")
    old, old_warned = validated_with_warnings(validate_recipe_config, "config", sequence,
                                              "reward.window=12")
    assert warned == [] and len(old_warned) == 1
    assert old_warned[0].startswith("config reward.window=12 is deprecated and read as "
                                    "reward.options.window=12; set that instead "
                                    "(+reward.options.window=12 on the command line")
    for cfg in (new, old):
        assert OmegaConf.to_container(cfg.reward.options) == {"window": 12}
        assert cfg.reward.window is None
        # The option reaches the reward: a d_sequence over windows of 12 embeddings.
        reward = reward_from_config(cfg, *torch.randn(2, 4))
        assert reward.window_length == 12 and reward.directional_heads.image.length == 11
    cfg, warned = validated_with_warnings(validate_recipe_config, "config", sequence,
                                          "reward.window=8", "reward.certainty_bandwidth=0.1",
                                          "reward.certainty_prior=1.0")
    assert warned == [] and OmegaConf.to_container(cfg.reward.options) == {}
    assert reward_from_config(cfg, *torch.randn(2, 4)).window_length == 8
    cfg, warned = validated_with_warnings(validate_recipe_config, "config", "reward.directional=d3",
                                          "reward.certainty_scaling=true",
                                          "reward.certainty_prior=2")
    assert OmegaConf.to_container(cfg.reward.options) == {"certainty_prior": 2.0}
    assert warned[0].startswith("config reward.certainty_prior=2.0 is deprecated")
    assert reward_from_config(cfg, *torch.randn(2, 4)).certainty.prior == 2.0
    with pytest.raises(ValueError, match=r"config reward\.window=12 and reward\.options\.window"
                                         r"=10 disagree"):
        validate_recipe_config(composed("config", sequence, "reward.window=12",
                                        "+reward.options.window=10"))
    with pytest.raises(ValueError, match=r"config reward\.options\.window=4 is invalid: expected "
                                         r"an option of furl or d3: they declare none"):
        validate_recipe_config(composed("config", "+reward.options.window=4"))
    with pytest.raises(ValueError, match=r"reward\.options\.certainty_bandwidth=0\.2 is invalid"
                                         r".*\(set as the deprecated reward\.certainty_"
                                         r"bandwidth\)"):
        validate_recipe_config(composed("config", "reward.certainty_bandwidth=0.2"))
    # The offline benchmark: the option of any listed variant, each variant gets its own.
    listed = ["reward.positional=none", "reward.directional=[d3,d_sequence]"]
    cfg, warned = validated_with_warnings(validate_reward_quality_config, "evaluate_rewards",
                                          *listed, "reward.window=4")
    assert OmegaConf.to_container(cfg.reward.options) == {"window": 4} and len(warned) == 1
    assert reward_from_config(cfg, *torch.randn(2, 4), variant="d_sequence").window_length == 4
    with pytest.raises(ValueError, match=r"reward\.options\.window=4 is invalid: expected an "
                                         r"option of d3 or d_certainty: certainty_bandwidth, "
                                         r"certainty_prior"):
        validate_reward_quality_config(composed("evaluate_rewards", "reward.positional=none",
                                                "reward.directional=[d3,d_certainty]",
                                                "+reward.options.window=4"))
