"""Random-goal tasks (``env.goal=random``) and periodic evaluation (``eval.*``): layouts drawn
anew at every reset from streams of their own, experts on them, and evaluation episodes that stay
out of training, run deterministically and resume on schedule."""

import csv
import json

import numpy as np
import pytest
import sac_temporal
import torch
from helpers import RECIPES, config, episode_csv_rows
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal

from temporal_torchrl.configs.rules import validate_recipe_config
from temporal_torchrl.envs import collect_expert_episodes, make_temporal_env
from temporal_torchrl.envs.metaworld_env import MetaworldEnv, layout_generator
from temporal_torchrl.params import EnvParams
from temporal_torchrl.runs import RunDirectory, default_run_dir
from temporal_torchrl.training.evaluation import PolicyEvaluation

GOAL = slice(36, 39)


def goals(env: MetaworldEnv, resets: int) -> list[tuple[float, ...]]:
    """The goal of each of ``resets`` layouts, as the agent observes it."""
    return [tuple(env.reset()["observation"][GOAL].tolist()) for _ in range(resets)]


# ---- layouts


def test_random_layouts_differ_across_resets_and_repeat_with_the_seed():
    drawn = goals(MetaworldEnv("drawer-open", 3, goal="random"), 6)
    assert len(set(drawn)) == 6
    assert goals(MetaworldEnv("drawer-open", 3, goal="random"), 6) == drawn
    assert not set(goals(MetaworldEnv("drawer-open", 4, goal="random"), 6)) & set(drawn)
    # The observed goal is the layout's true goal (random goals are goal-observable).
    env = MetaworldEnv("window-close", 0, goal="random")
    env.reset()
    np.testing.assert_allclose(env.reset()["observation"][GOAL].numpy(), env.goal_position,
                               rtol=1e-6)
    # Fixed goals keep one layout, and hide it, as before.
    fixed = MetaworldEnv("drawer-open", 3)
    assert goals(fixed, 3) == [(0.0, 0.0, 0.0)] * 3
    positions = {tuple(fixed.reset()["observation"][4:7].tolist()) for _ in range(3)}
    assert len(positions) == 1


def test_the_streams_of_one_seed_share_no_layout():
    """Training workers, experts and evaluation each draw their own layouts; the draws are
    Metaworld's own (its reset space, through the stream's generator)."""
    drawn = {(stream, index): goals(MetaworldEnv("window-open", 0, goal="random", stream=stream,
                                                 stream_index=index), 5)
             for stream, index in [("training", 0), ("training", 1), ("experts", 0),
                                   ("evaluation", 0)]}
    every = [goal for layouts in drawn.values() for goal in layouts]
    assert len(set(every)) == len(every)
    # Independent of the env: the first training layout is a draw of the stream's generator
    # from the task's reset space, the second one (Metaworld's reset runs `reset_model` twice:
    # in its own `reset` and again in MuJoCo's, and each draws).
    env = MetaworldEnv("window-open", 0, goal="random")
    space = env.metaworld_env._random_reset_space
    generator = layout_generator(0, "training", 0)
    _, expected = (generator.uniform(space.low, space.high) for _ in range(2))
    env.reset()
    np.testing.assert_allclose(env.metaworld_env._last_rand_vec, expected)


def test_parallel_workers_never_share_a_stream():
    """Each worker is built from the ParallelEnv's own env function and that worker's kwargs, as
    its process builds it (built here, in-process: spawning two workers costs about 40 s on two
    busy cores, and was run so once, with the same result)."""
    env = make_temporal_env("window-close", 5, num_envs=2, max_episode_steps=10, goal="random")
    workers = [env.create_env_fn[index](**env.create_env_kwargs[index]) for index in range(2)]
    first = [worker.reset()["observation"][GOAL].tolist() for worker in workers]
    for index in range(2):
        alone = MetaworldEnv("window-close", 5, goal="random", stream_index=index)
        assert first[index] == alone.reset()["observation"][GOAL].tolist()
    assert first[0] != first[1]


@pytest.mark.parametrize("task", ["window-close", "drawer-open"])
def test_the_expert_succeeds_on_random_layouts(task):
    """Measured over 12 layouts (docs/guides/protocols.md has the rate over 50 on six tasks)."""
    episodes = collect_expert_episodes(task, 0, num_episodes=12, goal="random",
                                       steps_after_success=0)
    rate = sum(bool(episode["next", "success"].any()) for episode in episodes) / len(episodes)
    assert rate >= 0.9, f"{task}: the expert succeeded on {rate:.0%} of 12 random layouts"
    layouts = {tuple(episode["observation"][0, GOAL].tolist()) for episode in episodes}
    assert len(layouts) == 12


# ---- evaluation


def small_actor(seed: int = 0) -> ProbabilisticActor:
    torch.manual_seed(seed)
    net = torch.nn.Sequential(MLP(in_features=39, out_features=8, num_cells=[16]),
                              NormalParamExtractor())
    return ProbabilisticActor(TensorDictModule(net, ["observation"], ["loc", "scale"]),
                              in_keys=["loc", "scale"], distribution_class=TanhNormal)


def test_evaluation_is_deterministic_given_the_parameters():
    actor = small_actor()
    evaluation = PolicyEvaluation(
        EnvParams("window-close", goal="random", max_episode_steps=30), episodes=3)
    torch.manual_seed(1)
    first = evaluation(actor)
    torch.manual_seed(2)  # no random number is drawn: another generator state changes nothing
    assert evaluation(actor) == first
    # It is the mean action on the same held-out layouts, whatever ran between evaluations.
    evaluation.env.reset()
    assert evaluation(actor) == first
    assert first["episodes"] == 3 and first["episode_length"] == 30.0
    assert first["return"] == -30.0 * (1 - first["success_rate"]) or first["success_rate"] > 0


def test_evaluation_episodes_stay_out_of_replay_and_training_metrics(tmp_path):
    plain = config(tmp_path / "plain", "train.episodes=4")
    evaluated = config(tmp_path / "evaluated", "train.episodes=4", "eval.every=2",
                       "eval.episodes=2", "logger.backend=csv")
    sac_temporal.train(plain)
    summary = sac_temporal.train(evaluated)
    plain_dir, evaluated_dir = tmp_path / "plain" / "run", tmp_path / "evaluated" / "run"
    assert episode_csv_rows(evaluated_dir) == episode_csv_rows(plain_dir)
    assert (sorted(path.name for path in (evaluated_dir / "replay").iterdir())
            == sorted(path.name for path in (plain_dir / "replay").iterdir()))
    with (evaluated_dir / "eval.csv").open() as file:
        rows = list(csv.DictReader(file))
    assert [(row["episode"], row["env_steps"], row["episodes"]) for row in rows] == [
        ("2", "40", "2"), ("4", "80", "2")]
    evaluation_points = [json.loads(line) for line in (evaluated_dir / "metrics.jsonl").open()
                         if '"eval/' in line]
    assert [point["step"] for point in evaluation_points] == [40, 80]
    assert summary["env_steps"] == 80 and summary["evaluation"]["evaluations"] == 2
    assert summary["evaluation"]["last_episode"] == 4
    assert "evaluation" in summary["phase_seconds"]


def test_evaluation_resumes_on_schedule_after_a_kill(tmp_path):
    common = ["train.episodes=4", "eval.every=1", "eval.episodes=1", "env.goal=random"]
    sac_temporal.train(config(tmp_path / "reference", *common))
    sac_temporal.train(config(tmp_path, *common, "train.stop_after_episodes=2"))
    run = RunDirectory(tmp_path / "run")
    # killed after evaluating episode 3, before its checkpoint: that row is taken again
    run.append_evaluation({"episode": 3, "env_steps": 60, "episodes": 1, "success_rate": 1.0,
                           "final_success_rate": 1.0, "return": 0.0, "episode_length": 20})
    summary = sac_temporal.train(config(tmp_path, *common, "resume=true"))
    reference = RunDirectory(tmp_path / "reference" / "run")
    assert [row["episode"] for row in run.evaluation_rows()] == [1, 2, 3, 4]
    assert run.evaluation_rows() == reference.evaluation_rows()
    assert summary["evaluation"] == reference.summary()["evaluation"]


def test_a_random_goal_run_trains_on_a_new_layout_each_episode(tmp_path):
    cfg = config(tmp_path, "env.goal=random", "train.episodes=3", "train.preload_positives=1",
                 "output_dir=null", f"runs_dir={tmp_path}")
    summary = sac_temporal.train(cfg)
    run_dir = default_run_dir(validate_recipe_config(cfg))
    assert run_dir.parent.name.endswith("_preload1_randomgoal")
    replay = RunDirectory(run_dir).replay
    first_goals = {tuple(replay.load(index)["observation"][0, GOAL].tolist())
                   for index in replay.indices()}
    assert len(first_goals) == 4  # the preloaded expert's layout and the three episodes'
    assert summary["config"]["env"]["goal"] == "random"


# ---- refused


@pytest.mark.parametrize(("override", "message"), [
    ("eval.every=0", "config eval.every=0 is invalid: expected an integer >= 1, or null."),
    ("eval.episodes=-1", "config eval.episodes=-1 is invalid: expected an integer >= 1."),
    ("env.goal=sometimes", "config env.goal='sometimes' is invalid: expected one of fixed, "
     "random."),
])
def test_bad_goal_and_evaluation_settings_are_refused(tmp_path, override, message):
    with pytest.raises(ValueError) as error:
        validate_recipe_config(config(tmp_path, override))
    assert message in str(error.value)


def test_positives_of_a_fixed_layout_are_refused_for_random_goals(tmp_path):
    source = config(tmp_path / "source", "train.episodes=1", "train.save_positives=true")
    OmegaConf.update(source, "train.preload_positives", 1)
    sac_temporal.train(source)
    with pytest.raises(ValueError, match=r"was trained with env\.goal='fixed', this run has "
                                         r"env\.goal='random'.*layouts \(env\.seed, env\.goal\)"):
        sac_temporal.train(config(tmp_path, "env.goal=random", "train.preload_positives=1",
                                  f"train.positives_from={tmp_path / 'source' / 'run'}"))


def test_the_furl_paper_protocol_is_furls_code(tmp_path):
    """fuyw/FuRL@6316e6c: max_timesteps 1e6, start_timesteps 1e4, eval_freq 1e5 env steps, 10
    eval episodes on random goals, l2_margin 0.25, rho 0.05 (preset=furl), no preload."""
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = validate_recipe_config(compose("config", overrides=["preset=furl",
                                                                  "protocol=furl_paper"]))
    steps = cfg.env.max_episode_steps
    assert (cfg.env.goal, cfg.train.preload_positives) == ("random", 0)
    assert cfg.train.episodes * steps == 1_000_000 and cfg.train.random_steps == 10_000
    assert (cfg.eval.every * steps, cfg.eval.episodes) == (100_000, 10)
    assert (cfg.reward.l2_margin, cfg.reward.rho) == (0.25, 0.05)
