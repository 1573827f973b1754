"""Scripted-expert episodes: success, layout, cut after success, frames equal to training frames."""

import pytest
import torch
from tensordict import TensorDict

from temporal_torchrl.envs import (
    EVALUATION_TASKS,
    collect_expert_episodes,
    collect_successful_experts,
    first_success_index,
    make_env,
)
from temporal_torchrl.params import EnvParams


@pytest.mark.parametrize("task", EVALUATION_TASKS)
def test_expert_succeeds_with_noise_and_is_cut_after_success(task):
    episode, = collect_expert_episodes(task, seed=0, noise=0.1, steps_after_success=5)
    first = first_success_index(episode)
    assert len(episode) == first + 6
    assert episode["next", "success"][first].item() and not episode["next", "success"][:first].any()
    # The cut is an episode end (truncation), visible to replay-buffer samplers.
    assert episode["next", "truncated"][-1].item() and episode["next", "done"][-1].item()
    assert not episode["next", "done"][:-1].any() and not episode["next", "terminated"].any()
    # Stored observations stay goal-hidden, as in training, although the expert saw the goal.
    assert torch.all(episode["observation"][:, 36:39] == 0)
    assert torch.equal(episode["next", "reward"], episode["next", "success"].float() - 1)


def test_episodes_have_the_rollout_layout():
    episode, = collect_expert_episodes("button-press-topdown", max_episode_steps=500)
    rollout = make_env("button-press-topdown", max_episode_steps=3).rollout(3)
    assert set(episode.keys(True)) == set(rollout.keys(True))
    for key in rollout.keys(True, True):
        assert episode[key].dtype == rollout[key].dtype
        assert episode[key].shape[1:] == rollout[key].shape[1:]
    assert torch.equal(episode["next", "observation"][:-1], episode["observation"][1:])


@pytest.mark.slow
def test_frames_match_the_training_frames():
    episode, = collect_expert_episodes("push", render=True, image_size=64, camera="corner3")
    training = make_env("push", render=True, image_size=64, camera="corner3")
    assert torch.equal(episode["pixels"][0], training.reset()["pixels"])
    assert torch.equal(episode["next", "pixels"][:-1], episode["pixels"][1:])
    goal_frame = episode["next", "pixels"][first_success_index(episode)]
    assert goal_frame.shape == (64, 64, 3) and goal_frame.dtype == torch.uint8
    # Replaying the first actions in a training env gives the same frames.
    replay = training.rollout(10, policy=_replay(episode["action"]))
    assert torch.equal(replay["next", "pixels"], episode["next", "pixels"][:10])


def _replay(actions):
    steps = iter(actions)
    return lambda tensordict: tensordict.set("action", next(steps))


def test_noise_makes_episodes_differ_and_the_generator_seed_reproduces_them():
    first, second = collect_expert_episodes("reach", num_episodes=2, noise=0.1)
    assert not torch.equal(first["action"][:5], second["action"][:5])
    again, = collect_expert_episodes("reach", num_episodes=1, noise=0.1)
    assert torch.equal(again["action"], first["action"])
    other, = collect_expert_episodes("reach", noise=0.1, generator_seed=123)
    assert not torch.equal(other["action"][:5], first["action"][:5])
    quiet = collect_expert_episodes("reach", num_episodes=2, noise=0.0)
    assert torch.equal(quiet[0]["action"], quiet[1]["action"])


def test_episode_without_success_runs_to_the_end():
    episode, = collect_expert_episodes("door-open", max_episode_steps=4)
    assert len(episode) == 4 and episode["next", "truncated"][-1].item()
    with pytest.raises(ValueError, match="never succeeds"):
        first_success_index(episode)


def test_whole_episodes_are_kept_when_asked():
    episode, = collect_expert_episodes("button-press-topdown", steps_after_success=None,
                                       max_episode_steps=120)
    assert len(episode) == 120 and first_success_index(episode) < 100
    assert episode["next", "truncated"][-1].item() and not episode["next", "done"][:-1].any()


def test_successful_experts_are_the_first_round_when_it_succeeds():
    """The first round draws the noise of ``collect_expert_episodes`` itself (generator seeded
    by the layout's seed), so the preloaded positives and the benchmark's experts are those
    episodes."""
    experts = collect_successful_experts("reach", 2)
    plain = collect_expert_episodes("reach", 0, num_episodes=2)
    assert all(torch.equal(a["action"], b["action"]) for a, b in zip(experts, plain, strict=True))
    assert collect_successful_experts("reach", 0) == []


def test_successful_experts_give_up_after_max_attempts_episodes_per_episode_wanted():
    """Failed episodes are replaced in further rounds until ``max_attempts`` episodes per episode
    wanted were tried; then an error says how many succeeded."""
    with pytest.raises(RuntimeError, match=r"door-open \(noise 0.1\) succeeded in only 0 of 4 "
                                           r"episodes, 2 wanted"):
        collect_successful_experts(EnvParams("door-open", max_episode_steps=4), 2,
                                   max_attempts=2)


def test_first_success_index():
    success = torch.tensor([False, False, True, False, True]).unsqueeze(-1)
    episode = TensorDict({"next": {"success": success}}, [5])
    assert first_success_index(episode) == 2


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="noise"):
        collect_expert_episodes("push", noise=-0.1)
    with pytest.raises(ValueError, match="steps_after_success"):
        collect_expert_episodes("push", steps_after_success=-1)
    with pytest.raises(ValueError, match="Unknown task"):
        collect_expert_episodes("pushh")
