"""Task registry and fixed-goal Metaworld envs: layouts, episodes, specs, errors."""

import pytest
import torch
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.envs import (
    EVALUATION_TASKS,
    GENERIC_BASELINE,
    TASKS,
    MetaworldEnv,
    get_task,
    make_env,
)

EXPECTED_EVALUATION = {
    # name: (goal prompt, tailored baseline, RAS budget), from the prior implementations.
    "drawer-open": ("open a drawer", "closed drawer", 300),
    "door-open": ("open a door with a revolving joint", "closed door with a revolving joint", 400),
    "window-open": ("push and open a window", "closed window", 200),
    "window-close": ("push and close a window", "open window", 200),
    "push": ("push the puck to a goal", "puck on table not at goal", 1000),
    "button-press-topdown": ("press a button from the top", "unpressed button", 400),
}


def test_registry_holds_all_mt50_tasks_with_prompts():
    assert len(TASKS) == 50
    assert all(not name.endswith("-v3") and spec.env_id == f"{name}-v3"
               for name, spec in TASKS.items())
    assert all(spec.goal_prompt for spec in TASKS.values())
    assert len({spec.goal_prompt for spec in TASKS.values()}) == 50
    assert GENERIC_BASELINE == "robot arm beside table"


def test_evaluation_tasks_carry_thesis_values():
    assert EVALUATION_TASKS == tuple(EXPECTED_EVALUATION)
    for name, (prompt, baseline, budget) in EXPECTED_EVALUATION.items():
        spec = get_task(name)
        assert (spec.goal_prompt, spec.tailored_baseline, spec.ras_budget) == (
            prompt, baseline, budget)
        assert spec.is_evaluation_task and spec.baseline == baseline
    other = get_task("reach")
    assert other.tailored_baseline is None and other.baseline == GENERIC_BASELINE
    assert get_task("reach-v3") is other


def test_every_task_has_an_expert():
    assert all(hasattr(spec.make_expert(), "get_action") for spec in TASKS.values())


def test_unknown_task_is_refused_with_the_valid_names():
    with pytest.raises(ValueError, match="drawer-open") as error:
        get_task("drawer-opne")
    assert "'drawer-opne'" in str(error.value) and "button-press-topdown" in str(error.value)
    with pytest.raises(ValueError, match="Unknown task"):
        make_env("not-a-task")


@pytest.mark.parametrize("image_size", [0, -3, (64, 0)])
def test_non_positive_image_size_is_refused(image_size):
    with pytest.raises(ValueError, match="image_size"):
        make_env("push", render=True, image_size=image_size)


def test_unknown_camera_is_refused_with_the_valid_cameras():
    with pytest.raises(ValueError, match="corner2") as error:
        make_env("push", render=True, image_size=32, camera="corner9")
    assert "'corner9'" in str(error.value)


def test_bad_seed_and_episode_length_are_refused():
    with pytest.raises(ValueError, match="seed"):
        make_env("push", seed=-1)
    with pytest.raises(ValueError, match="seed"):
        make_env("push", seed="0")
    with pytest.raises(ValueError, match="max_episode_steps"):
        make_env("push", max_episode_steps=0)


@pytest.mark.parametrize("task", EVALUATION_TASKS)
def test_same_layout_on_every_reset_and_different_layouts_for_different_seeds(task):
    env = make_env(task, seed=0, max_episode_steps=10)
    first = env.reset()["observation"]
    env.rollout(10, break_when_any_done=False)  # move things, then come back
    second = env.reset()["observation"]
    assert torch.equal(first, second)
    other_seed = make_env(task, seed=1)
    # The (hidden) goal position is part of every evaluation task's sampled layout.
    assert (env.goal_position != other_seed.goal_position).any()
    assert torch.equal(make_env(task, seed=1).reset()["observation"],
                       other_seed.reset()["observation"])


def test_goal_hidden_by_default_and_observable_on_request():
    hidden = make_env("push", seed=0)
    observation = hidden.reset()["observation"]
    assert observation.dtype == torch.float32 and observation.shape == (39,)
    assert torch.all(observation[36:39] == 0)
    visible = make_env("push", seed=0, goal_observable=True)
    goal = visible.reset()["observation"][36:39]
    assert torch.allclose(goal, torch.as_tensor(visible.goal_position, dtype=torch.float32))
    assert torch.allclose(observation[:36], visible.reset()["observation"][:36])


def test_episodes_end_by_truncation_with_success_and_sparse_reward():
    env = make_env("push", max_episode_steps=5)
    reset = env.reset()
    assert reset["success"].dtype == torch.bool and reset["success"].shape == (1,)
    assert not reset["success"].any()
    rollout = env.rollout(10, break_when_any_done=False)
    done = rollout["next", "done"].squeeze(-1)
    assert done.tolist() == [False] * 4 + [True] + [False] * 4 + [True]
    assert torch.equal(rollout["next", "truncated"], rollout["next", "done"])
    assert not rollout["next", "terminated"].any()
    success = rollout["next", "success"]
    assert success.dtype == torch.bool and success.shape == (10, 1)
    assert torch.equal(rollout["next", "reward"], success.float() - 1)
    assert rollout["next", "reward"].dtype == torch.float32


def test_default_episode_lasts_500_steps():
    rollout = make_env("reach").rollout(600)
    assert len(rollout) == 500
    assert rollout["next", "truncated"][-1].item() and not rollout["next", "done"][:-1].any()


@pytest.mark.filterwarnings("ignore:Constant")
def test_success_flag_follows_metaworld():
    env = make_env("reach", seed=0, goal_observable=True)
    tensordict = env.reset()
    expert = get_task("reach").make_expert()
    for _ in range(100):
        action = expert.get_action(tensordict["observation"].double().numpy())
        tensordict["action"] = torch.as_tensor(action, dtype=torch.float32).clamp(-1, 1)
        tensordict = env.step(tensordict)
        if tensordict["next", "success"].item():
            break
        tensordict = tensordict["next"]
    assert tensordict["next", "success"].item() and tensordict["next", "reward"].item() == 0.0


@pytest.mark.parametrize("render", [False, True])
def test_specs_pass_check_env_specs(render):
    env = make_env("drawer-open", render=render, image_size=32, max_episode_steps=20)
    check_env_specs(env)
    base = env.base_env if render else env
    assert isinstance(base, MetaworldEnv)
    assert ("pixels" in env.observation_spec.keys()) == render
