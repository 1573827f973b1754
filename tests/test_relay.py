"""FuRL's relay exploration: the schedule against the release's rule written out, the policy's
action mixing, and the recipe's relay runs (fraction, stage 2, bit-exact resume)."""

import csv

import pytest
import sac_temporal
import torch
from helpers import config
from helpers import episode_csv_rows as episode_rows
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.data import Bounded

from temporal_torchrl.defaults import RELAY_PERIODS
from temporal_torchrl.objectives import StackedCriticSACLoss
from temporal_torchrl.params import RelayParams
from temporal_torchrl.runs import RunDirectory
from temporal_torchrl.training.relay import RelayPolicy, RelaySchedule


def release_agents(lengths, periods):
    """The release's loop (train_furl.py) written out: ``policies[(ep_step // relay_freq) % 2]``
    with ``policies`` reversed at every episode end."""
    policies, agents = ["vlm", "sac"], []
    for length, relay_freq in zip(lengths, periods, strict=True):
        agents += [policies[(ep_step // relay_freq) % 2] == "sac" for ep_step in range(length)]
        policies = policies[::-1]
    return agents


def test_schedule_follows_the_release_rule():
    lengths = [120, 75, 300, 60, 500, 233]
    schedule = RelaySchedule(num_envs=1, seed=3)
    periods, agents = [], []
    for length in lengths:
        periods.append(int(schedule.period[0]))
        for step in range(length):
            agents.append(bool(schedule.relay_mask()[0]))
            schedule.advance(ended=[0] if step == length - 1 else [])
    assert agents == release_agents(lengths, periods)
    assert schedule.total_relay_steps == sum(agents)
    # each episode's period is one of the release's, redrawn per episode
    draws = RelaySchedule(num_envs=1, seed=0)
    drawn = []
    for _ in range(200):
        drawn.append(int(draws.period[0]))
        draws.advance(ended=[0])
    assert set(drawn) == set(RELAY_PERIODS)


def test_schedule_per_env_and_threshold():
    schedule = RelaySchedule(2, RelayParams(periods=[3], threshold=10))
    schedule.advance(ended=[1])  # env 1 starts its second episode: with the relay agent
    assert schedule.relay_mask().tolist() == [False, True]
    schedule.end_if_enough(9)
    assert schedule.active
    schedule.end_if_enough(10)
    assert not schedule.active and not schedule.relay_mask().any()
    restored = RelaySchedule(2, RelayParams(periods=[3], threshold=10))
    restored.load_state_dict(schedule.state_dict())
    assert not restored.active and restored.step.tolist() == [1, 0]


def constant_actor(value: float) -> TensorDictModule:
    return TensorDictModule(lambda obs: torch.full((*obs.shape[:-1], 4), value),
                            in_keys=["observation"], out_keys=["action"])


def test_policy_gives_relay_envs_the_noisy_relay_action():
    spec = Bounded(-1.0, 1.0, shape=(4,))
    schedule = RelaySchedule(3, RelayParams(periods=[5], noise=0.2))
    schedule.advance(ended=[1])  # env 1 on the relay agent
    policy = RelayPolicy(constant_actor(0.25), constant_actor(0.9), schedule, spec)
    actions = policy(TensorDict({"observation": torch.zeros(3, 39)}, [3]))["action"]
    assert torch.equal(actions[[0, 2]], torch.full((2, 4), 0.25))
    assert not torch.equal(actions[1], torch.full((4,), 0.9))  # noised ...
    assert bool((actions[1] <= 1.0).all()) and bool((actions[1] >= -1.0).all())  # ... and clipped
    many = torch.stack([policy(TensorDict({"observation": torch.zeros(3, 39)}, [3]))["action"][1]
                        for _ in range(2000)])
    # E[min(X, 1)] for X ~ N(0.9, 0.2^2), from the normal's cdf and density at 1
    normal = torch.distributions.Normal(0.9, 0.2)
    one = torch.tensor(1.0)
    cdf, density = normal.cdf(one), normal.log_prob(one).exp()
    expected = float(0.9 * cdf - 0.2 ** 2 * density + (1 - cdf))
    assert float(many.mean()) == pytest.approx(expected, abs=0.01)
    schedule.active = False
    assert torch.equal(policy(TensorDict({"observation": torch.zeros(3, 39)}, [3]))["action"],
                       torch.full((3, 4), 0.25))


def test_stage_one_run_relays_every_other_episode(tmp_path, monkeypatch):
    """20-step episodes, periods longer than an episode: by the release's rule episode 2 of 3
    (0-based 1) runs on the relay agent from its first step, the others on the VLM agent; the
    relay agent learns from the VLM agent's batches with their sparse task reward."""
    from temporal_torchrl.data import EpisodeReplayBuffer

    batches: dict[int, list] = {}
    forward = StackedCriticSACLoss.forward

    def recording_forward(self, tensordict):
        batches.setdefault(id(self), []).append(tensordict.select(
            "observation", ("next", "reward")).clone())
        return forward(self, tensordict)

    sampled = []
    sample = EpisodeReplayBuffer.sample

    def recording_sample(self, *args, **kwargs):
        batch = sample(self, *args, **kwargs)
        sampled.append(batch["next", "success"].clone())
        return batch

    monkeypatch.setattr(StackedCriticSACLoss, "forward", recording_forward)
    monkeypatch.setattr(EpisodeReplayBuffer, "sample", recording_sample)
    summary = sac_temporal.train(config(tmp_path, "logger.backend=csv", "logger.log_every=5"))
    vlm, relay = batches.values()  # the VLM agent's loss is built (and called) first
    assert len(vlm) == len(relay) == len(sampled) == 40
    for own, theirs, success in zip(vlm, relay, sampled, strict=True):
        assert torch.equal(own["observation"], theirs["observation"])
        assert torch.equal(theirs["next", "reward"], success.float() - 1.0)
        assert not torch.equal(own["next", "reward"], theirs["next", "reward"])
    assert summary["relay_steps"] == 20
    fractions = next((tmp_path / "run" / "logs").rglob("train/relay_fraction.csv"))
    with fractions.open() as file:
        assert [float(row[1]) for row in csv.reader(file)] == [0.0, 1.0, 0.0]
    assert "relay/loss_qvalue" in summary["last_metrics"]


def test_relay_run_resumes_bit_exactly(tmp_path):
    common = ["train.episodes=4", "train.relay_periods=[7]"]
    straight = sac_temporal.train(config(tmp_path / "a", *common))
    sac_temporal.train(config(tmp_path / "b", *common, "train.stop_after_episodes=2"))
    resumed = sac_temporal.train(config(tmp_path / "b", *common, "resume=true"))
    assert resumed["relay_steps"] == straight["relay_steps"] > 0
    assert episode_rows(tmp_path / "a" / "run") == episode_rows(tmp_path / "b" / "run")
    first, second = (RunDirectory(tmp_path / name / "run").load_checkpoint().relay
                     for name in ("a", "b"))
    for key, value in first["loss"].items():
        torch.testing.assert_close(second["loss"][key], value, msg=key, rtol=0, atol=0)


def test_stage_two_positives_switch_relay_off_and_leave_the_run_unchanged(tmp_path, capsys):
    common = ["protocol=stage2", "train.preload_positives=1", "train.episodes=2",
              "train.relay_threshold=5"]
    with_relay = sac_temporal.train(config(tmp_path / "a", *common))
    assert "relay exploration: off (the positives already reach" in capsys.readouterr().out
    without = sac_temporal.train(config(tmp_path / "b", *common, "train.relay=false"))
    assert with_relay["relay_steps"] == 0
    assert episode_rows(tmp_path / "a" / "run") == episode_rows(tmp_path / "b" / "run")
    first, second = (RunDirectory(tmp_path / name / "run").load_checkpoint().sac_loss
                     for name in ("a", "b"))
    for key, value in first.items():
        torch.testing.assert_close(second[key], value, msg=key, rtol=0, atol=0)
    assert without["relay_steps"] == 0
