"""Throughput options: several envs per run (batched transforms, partial resets, per-env
episodes, the update-to-data ratio), devices through one code path, and compiled updates that
match eager ones."""

import pytest
import sac_temporal
import torch
from helpers import config
from helpers import episode_csv_rows as episode_rows
from torch._dynamo.utils import counters

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.envs import make_temporal_env, make_temporal_reward
from temporal_torchrl.runs import RunDirectory
from temporal_torchrl.training import factories


def forget_compiled_graphs() -> None:
    """Empty dynamo's caches and counters: a function compiled after this makes new graphs
    (none are reused from an earlier test), which :func:`compiled_graphs` counts."""
    torch._dynamo.reset()
    counters.clear()


def compiled_graphs() -> int:
    """The graphs torch.compile (dynamo) made since :func:`forget_compiled_graphs`: 0 when a
    function said to be compiled ran eager."""
    return counters["stats"]["unique_graphs"]


@pytest.mark.slow
def test_batched_env_keeps_each_envs_history_across_resets():
    """Two worker envs, 4-step episodes, k = 2: s_{t-k} and s_0 of every env and step are read
    off that env's own embeddings, clamped at each episode's start, and the reward is the
    single-state reward of those inputs."""
    encoder = load_encoder("state", dim=8)
    reward = make_temporal_reward("drawer-open", encoder, positional="furl", directional="d3",
                                  rho=1.0, lambda_=2.0, k=2)
    env = make_temporal_env("drawer-open", encoder=encoder, reward=reward, max_episode_steps=4,
                            num_envs=2)
    try:
        rollout = env.rollout(10, break_when_any_done=False)  # [2, 10]: resets after steps 4, 8
    finally:
        env.close()
    assert rollout.batch_size == (2, 10)
    for index in range(2):
        steps = rollout[index]
        for t in range(10):
            episode_step = t % 4 + 1  # s_1 .. s_4 within each episode
            start = t - (episode_step - 1)  # the transition that left s_0
            s_0 = steps["embedding"][start]
            expected_previous = (steps["next", "embedding"][t - 2] if episode_step > 2 else s_0)
            torch.testing.assert_close(steps["next", "initial_embedding"][t], s_0)
            torch.testing.assert_close(steps["next", "previous_embedding"][t], expected_previous)
        nxt = steps["next"]
        with torch.no_grad():
            expected = reward(nxt["embedding"], nxt["initial_embedding"],
                              nxt["previous_embedding"], nxt["success"])["reward"]
        torch.testing.assert_close(nxt["reward"], expected)
    # the two envs act independently (different random actions)
    assert not torch.equal(rollout[0]["next", "observation"], rollout[1]["next", "observation"])


@pytest.mark.parametrize(("utd_ratio", "expected_updates", "resume"),
                         [(1, 40, True), (0.5, 20, False)])
@pytest.mark.slow
def test_several_envs_insert_every_episode_keep_the_update_ratio_and_resume(
        tmp_path, utd_ratio, expected_updates, resume):
    """2 envs, 20-step episodes, 4 episodes = 40 vector steps. The first episodes end at vector
    step 20 (insertion after that step's updates), so updates run on vector steps 21..40:
    20 x 2 envs x utd_ratio. The same run stopped after 2 episodes and resumed gives the same
    episodes and SAC agent (checked once: at utd_ratio 1)."""
    common = ["env.num_envs=2", "train.episodes=4", "train.random_steps=10",
              "reward.directional=d3", f"train.utd_ratio={utd_ratio}"]
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"
    summary = sac_temporal.train(config(straight, *common))
    assert summary["updates"] == expected_updates
    assert summary["env_steps"] == 80 and summary["episodes"] == 4
    rows = episode_rows(straight / "run")
    assert [int(row["env_steps"]) for row in rows] == [40, 40, 80, 80]
    state = RunDirectory(straight / "run").load_checkpoint()
    assert state.inserted == 4
    stored = list(RunDirectory(straight / "run").replay_episodes(4))
    assert [len(episode) for episode in stored] == [21] * 4
    # the two envs of one round stored different trajectories
    assert not torch.equal(stored[0]["observation"], stored[1]["observation"])
    if not resume:
        return
    sac_temporal.train(config(resumed, *common, "train.stop_after_episodes=2"))
    again = sac_temporal.train(config(resumed, "resume=true", "train.episodes=4"))
    assert again["successes"] == summary["successes"]
    assert episode_rows(resumed / "run") == rows
    for key, value in state.sac_loss.items():
        torch.testing.assert_close(
            RunDirectory(resumed / "run").load_checkpoint().sac_loss[key], value, msg=key)


@pytest.mark.parametrize("stage", [1, 2])
def test_compiled_reward_head_losses_match_the_eager_ones(tmp_path, stage):
    """compile.enabled on a CPU: the trainer's reward-head losses run through torch.compile
    (inductor) and give the eager losses' values and gradients on the same batch, within float
    tolerance, in stage 1 (negatives alone: one part per loss, the case inductor once returned
    without its gradient) and stage 2."""
    from helpers import make_episode

    from temporal_torchrl.data import EpisodeReplayBuffer
    from temporal_torchrl.data import episode_rows as stored_rows

    buffer = EpisodeReplayBuffer(capacity=200, k=2, gap=5)
    buffer.extend(stored_rows(make_episode(0, 20), embedding_dtype=torch.float32))
    buffer.extend(stored_rows(make_episode(1, 20, successes=(12,) if stage == 2 else ()),
                              embedding_dtype=torch.float32))
    cfg = config(tmp_path, "reward.directional=d3", "compile.enabled=true")
    reward = make_temporal_reward("drawer-open", load_encoder("state", dim=4),
                                  positional="furl", directional="d3", k=buffer.k)
    trainer = factories.make_reward_trainer(cfg, reward, torch.ones(4), buffer)
    batch = buffer.finetuning.sample(16)
    assert trainer.stage == stage
    for loss, compiled in zip(trainer.losses, trainer._forwards, strict=True):
        parameters = list(loss.parameters())
        forget_compiled_graphs()
        values = [forward(batch)[loss.loss_key] for forward in (loss, compiled)]
        assert compiled_graphs() > 0, f"{loss.loss_key}: its forward compiled no graph"
        eager_grads, compiled_grads = (torch.autograd.grad(value, parameters, allow_unused=True)
                                       for value in values)
        torch.testing.assert_close(values[1], values[0], rtol=1e-5, atol=1e-6)
        for eager, other in zip(eager_grads, compiled_grads, strict=True):
            if eager is not None:
                torch.testing.assert_close(other, eager, rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_compiled_sac_update_matches_the_eager_one(tmp_path):
    """compile.enabled compiles the SAC update (on a CPU too): from the same weights and seed,
    the compiled update takes the eager one's random draws (compile_options: fallback_random)
    and gives its losses at each of 3 updates and its parameters after them, within float
    tolerance."""
    env = factories.make_environment(config(tmp_path, "reward.directional=d3"), None, None)
    batches = [env.rollout(16, break_when_any_done=False) for _ in range(3)]
    results = []
    for compiled in (False, True):
        cfg = config(tmp_path, "reward.directional=d3", f"compile.enabled={compiled}")
        torch.manual_seed(0)
        actor, critics = factories.make_sac_agent(cfg, env, Devices.of(cfg))
        loss, optimizer = factories.make_sac_loss(cfg, actor, critics, 4)
        update = factories.make_sac_update(cfg, loss, optimizer)
        torch.manual_seed(1)
        forget_compiled_graphs()
        losses = [update(batch.clone()) for batch in batches]
        # Compiled: dynamo made graphs of the update (and nothing while it ran eager).
        assert (compiled_graphs() > 0) == compiled, compiled_graphs()
        results.append((losses, [p.detach().clone() for p in loss.parameters()]))
    env.close()
    (eager_losses, eager_parameters), (compiled_losses, compiled_parameters) = results
    for eager, compiled in zip(eager_losses, compiled_losses, strict=True):
        for key in ("loss_actor", "loss_qvalue", "loss_alpha", "entropy"):
            torch.testing.assert_close(compiled[key], eager[key], rtol=1e-4, atol=1e-5,
                                       msg=key)
    for eager, compiled in zip(eager_parameters, compiled_parameters, strict=True):
        torch.testing.assert_close(compiled, eager, rtol=1e-4, atol=1e-5)


@pytest.mark.slow
def test_compiled_run_gives_the_eager_runs_episodes(tmp_path):
    """The recipe with compile.enabled (the SAC updates, the head losses, the relabelling
    reward and the policy compiled) against the same run eager: 3 episodes of 20 steps with
    updates from step 10 on, FuRL + D3 and relay, from the same seed: the same episodes (their
    stored observations, actions and embeddings, and their logged returns) within float
    tolerance; and so does an eager run stopped after its first episode and resumed compiled."""
    def run(name: str, *overrides: str) -> dict:
        return sac_temporal.train(config(tmp_path / name, "reward.directional=d3", *overrides))

    forget_compiled_graphs()
    run("eager", "compile.enabled=false")
    assert compiled_graphs() == 0
    run("compiled", "compile.enabled=true")
    assert compiled_graphs() >= 4  # the SAC update, the two head losses, the reward, the policy
    run("switched", "compile.enabled=false", "train.stop_after_episodes=1")
    forget_compiled_graphs()
    resumed = run("switched", "resume=true", "compile.enabled=true")
    assert compiled_graphs() > 0  # resumed compiled, not eager
    assert resumed["config"]["compile"]["enabled"] is True
    runs = {}
    for name in ("eager", "compiled", "switched"):
        directory = RunDirectory(tmp_path / name / "run")
        summary = directory.summary()
        runs[name] = (summary, list(directory.replay_episodes(summary["episodes"])),
                      episode_rows(tmp_path / name / "run"))
    eager_summary, eager, eager_rows = runs.pop("eager")
    for name, (summary, episodes, rows) in runs.items():
        assert summary["updates"] == eager_summary["updates"] > 0, name
        assert len(episodes) == len(eager) == 3, name
        for eager_episode, episode in zip(eager, episodes, strict=True):
            for key in ("observation", "action", "embedding"):
                torch.testing.assert_close(episode[key], eager_episode[key], rtol=1e-3,
                                           atol=1e-4, msg=f"{name}: {key}")
        for eager_row, row in zip(eager_rows, rows, strict=True):
            assert eager_row.keys() == row.keys()
            for key in ("return", "mean_vlm_reward"):
                assert float(row[key]) == pytest.approx(float(eager_row[key]), rel=1e-3,
                                                        abs=1e-4), (name, key)


def test_rendering_workers_embed_their_own_frames():
    """Each worker renders (EGL) its own env; one encoder forward embeds both frames, which
    match the single-env pipeline's frame after the same first action."""
    encoder = load_encoder("metaworld_small")
    batched = make_temporal_env("drawer-open", encoder=encoder, image_size=32,
                                max_episode_steps=5, num_envs=2)
    single = make_temporal_env("drawer-open", encoder=encoder, image_size=32,
                               max_episode_steps=5)
    try:
        start = batched.reset()
        reference = single.reset()
    finally:
        batched.close()
        single.close()
    assert start["embedding"].shape == (2, encoder.dim) and "pixels" not in start.keys()
    # the same layout: every worker's first frame is the single env's
    for index in range(2):
        torch.testing.assert_close(start["embedding"][index], reference["embedding"],
                                   rtol=1e-4, atol=1e-4)
