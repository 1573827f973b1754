"""One reward path: the env, the replay relabelling, SAC's batches and the finetuning losses all
see the same rewards for the same stored embeddings, checked value by value."""

import pytest
import sac_temporal
import torch
import torch.nn.functional as F
from helpers import config
from tensordict import TensorDict

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows, transition_index
from temporal_torchrl.objectives import PositionalRankingLoss, StackedCriticSACLoss
from temporal_torchrl.rewards import DIRECTIONAL, POSITIONAL, register_reward, unregister_reward
from temporal_torchrl.training import factories


def furl_plus_d3(reward, next_states: TensorDict) -> torch.Tensor:
    """r = (success - 1) + rho (csim(f_I(s), f_L(g)) + lambda csim(f^D_I(n(s) ⊕ n(s - s_{t-k})),
    f^D_L(g - b))), written out from thesis 3.1.3 and 4.3.2 with the heads' own layers."""
    s, s_prev = next_states["embedding"], next_states["previous_embedding"]
    g, b = reward.goal_embedding, reward.baseline_embedding
    positional = F.cosine_similarity(reward.positional_heads.image(s),
                                     reward.positional_heads.text(g).expand(len(s), -1), dim=-1)
    direction = s - s_prev
    image_input = torch.cat([F.normalize(s, dim=-1), F.normalize(direction, dim=-1)], -1)
    directional = F.cosine_similarity(reward.directional_heads.image(image_input),
                                      reward.directional_heads.text(g - b).expand(len(s), -1),
                                      dim=-1)
    task = next_states["success"].float().squeeze(-1) - 1.0
    return task + reward.rho * (positional + reward.lambda_ * directional)


def test_rendered_rollout_relabelled_from_the_buffer_gives_the_env_rewards(tmp_path):
    """Render -> embed (the shipped encoder) -> history -> reward in the env; the same episode
    inserted into the recipe's replay buffer and relabelled there: transition by transition, the
    same rewards, and both equal the equations written out."""
    cfg = config(tmp_path, "encoder.name=metaworld_small", "~encoder.options.dim",
                 "env.image_size=32", "env.max_episode_steps=12", "reward.k=3",
                 "replay_buffer.embedding_dtype=float32")
    torch.manual_seed(0)
    devices = Devices.of(cfg)
    encoder = factories.make_encoder(cfg, devices.encoder)
    reward = factories.make_reward(cfg, encoder, devices)
    env = factories.make_environment(cfg, encoder, reward)
    rollout = env.rollout(12, break_when_any_done=False)
    env.close()
    buffer = factories.make_replay_buffer(cfg, capacity=100, reward=reward, devices=devices)
    buffer.extend(episode_rows(rollout, embedding_dtype=torch.float32))
    rows = torch.arange(12)  # the episode's transitions, in order (steps = rows)
    batch = buffer[transition_index(rows, rows, cfg.reward.k)]  # relabelled by its transform
    with torch.no_grad():
        expected = furl_plus_d3(reward, batch["next"])
    env_rewards = rollout["next", "reward"].squeeze(-1)
    torch.testing.assert_close(batch["next", "reward"].squeeze(-1), env_rewards)
    torch.testing.assert_close(env_rewards, expected)
    # The history is real: s_{t+1-k} is s_0 for the first k - 1 transitions, then moves.
    torch.testing.assert_close(batch["next", "previous_embedding"][5], rollout["next",
                               "embedding"][2])
    assert env_rewards.unique().numel() > 6  # rewards vary along the episode


def test_sac_loss_receives_the_relabelled_rewards(tmp_path, monkeypatch):
    """Capture SAC's batches during a run: their rewards are those of the heads at that update,
    not the sparse task reward and not the values logged during collection."""
    made = []
    make_reward = factories.make_reward
    monkeypatch.setattr(factories, "make_reward",
                        lambda *args: made.append(make_reward(*args)) or made[-1])
    expected, received = [], []
    sample = EpisodeReplayBuffer.sample

    def recording_sample(self, *args, **kwargs):
        # Sampled right before its SAC update, after the heads' update: the heads of that update.
        batch = sample(self, *args, **kwargs)
        with torch.no_grad():
            expected.append((furl_plus_d3(made[0], batch["next"]),
                             batch["next", "success"].float().squeeze(-1) - 1.0))
        return batch

    forward = StackedCriticSACLoss.forward

    def recording_forward(self, tensordict):
        received.append(tensordict["next", "reward"].squeeze(-1).clone())
        return forward(self, tensordict)

    monkeypatch.setattr(EpisodeReplayBuffer, "sample", recording_sample)
    monkeypatch.setattr(StackedCriticSACLoss, "forward", recording_forward)
    # No relay: its agent's SAC loss learns from the sparse reward (tests/test_relay.py)
    sac_temporal.train(config(tmp_path, "reward.directional=d3", "reward.rho=1.0",
                              "reward.lambda_=4.0", "train.episodes=2", "train.relay=false"))
    assert len(received) == len(expected) == 20  # one update per step after the 1st episode
    for rewards, (relabelled, task) in zip(received, expected, strict=True):
        torch.testing.assert_close(rewards, relabelled)
        assert (rewards - task).abs().min() > 0  # the VLM part is there


def test_a_registered_reward_sees_the_same_history_everywhere(tmp_path):
    """A positional reward that records the s_{t-k} it is given, per state: the env, the
    relabelling and the finetuning loss must agree, and never pass None."""
    seen = {"env": {}, "relabel": {}, "finetune": {}}

    def recording(heads, s, *, g, s_prev=None, **unused):
        assert s_prev is not None, "every call site must pass s_prev"
        site = ("finetune" if torch.is_grad_enabled() else
                "env" if s.ndim == 1 else "relabel")
        for state, previous in zip(s.reshape(-1, s.shape[-1]),
                                   s_prev.reshape(-1, s.shape[-1]), strict=True):
            seen[site].setdefault(tuple(state.tolist()), set()).add(tuple(previous.tolist()))
        return POSITIONAL["furl"](heads, s, g=g)

    register_reward("recording_p", recording, kind="positional")
    try:
        sac_temporal.train(config(tmp_path, "reward.positional=recording_p",
                                  "reward.directional=none", "reward.k=4",
                                  "replay_buffer.embedding_dtype=float32", "train.episodes=2"))
    finally:
        unregister_reward("recording_p")
    assert all(seen.values()), {site: len(states) for site, states in seen.items()}
    for site in ("relabel", "finetune"):
        common = seen["env"].keys() & seen[site].keys()
        assert len(common) > 10, site
        for state in common:
            assert seen[site][state] == seen["env"][state], site


def test_a_window_reward_sees_the_same_window_everywhere(tmp_path):
    """d_sequence's input: a window reward records the window s_(t-K+1) .. s_t it is given with
    each observed state (the calls without a position): the env's history transform, the
    relabelled batches and the finetuning batches agree, the window ends at s_t, and it is
    padded with s_0 at each episode's start."""
    seen = {"env": {}, "relabel": {}, "finetune": {}}

    def recording(heads, s, *, s_prev=None, window=None, g, b, position=None, **unused):
        if position is None:
            assert window is not None, "every call site must pass the window"
            site = ("finetune" if torch.is_grad_enabled() else
                    "env" if s.ndim == 1 else "relabel")
            for state, states in zip(s.reshape(-1, s.shape[-1]),
                                     window.reshape(-1, *window.shape[-2:]), strict=True):
                assert torch.equal(states[-1], state)
                seen[site].setdefault(tuple(state.tolist()), set()).add(
                    tuple(map(tuple, states.tolist())))
        return DIRECTIONAL["d_sequence"](heads, s, s_prev=s_prev, window=window, g=g, b=b,
                                         position=position)

    register_reward("recording_d", recording, kind="directional", image_input="window")
    try:
        sac_temporal.train(config(tmp_path, "reward.positional=none",
                                  "reward.directional=recording_d", "+reward.options.window=6",
                                  "replay_buffer.embedding_dtype=float32", "train.episodes=2"))
    finally:
        unregister_reward("recording_d")
    assert all(seen.values()), {site: len(states) for site, states in seen.items()}
    # Each episode's first rewarded state s_1 has the window (s_0, .., s_0, s_1).
    padded = [window for windows in seen["env"].values() for window in windows
              if len(set(window[:-1])) == 1]
    assert len(padded) == 2, "one padded window per episode"
    for site in ("relabel", "finetune"):
        common = seen["env"].keys() & seen[site].keys()
        assert len(common) > 10, site
        for state in common:
            assert seen[site][state] == seen["env"][state], site


def spearman(values: torch.Tensor) -> float:
    """Rank correlation of ``values`` with time (no ties in continuous rewards)."""
    ranks = values.argsort().argsort().float()
    time = torch.arange(len(values), dtype=torch.float32)
    return float(torch.corrcoef(torch.stack([ranks, time]))[0, 1])


@pytest.mark.slow
def test_ranking_loss_learns_to_order_expert_states_by_time(tmp_path):
    """A learning sanity check: FuRL's heads finetuned on expert positives (pos-pos ranking) and
    random negatives rank the states of a held-out expert episode by time much better than the
    untrained heads do."""
    from temporal_torchrl.encoders import load_encoder
    from temporal_torchrl.envs import make_env
    from temporal_torchrl.rewards import TemporalReward

    cfg = config(tmp_path, "train.expert_steps_after_success=0", "env.max_episode_steps=500")
    torch.manual_seed(0)
    experts = factories.make_expert_episodes(cfg, None, 4)
    encoder = load_encoder("state", dim=32)
    buffer = EpisodeReplayBuffer(capacity=5000, k=5, gap=10)
    embed = encoder.embed
    for episode in experts[:3]:
        episode = episode.clone()
        episode["embedding"] = embed(episode["observation"])
        episode["next", "embedding"] = embed(episode["next", "observation"])
        buffer.extend(episode_rows(episode, embedding_dtype=torch.float32))
    env = make_env(cfg.env.task, cfg.env.seed, render=False, max_episode_steps=200)
    random_episode = env.rollout(200)  # uniform random actions: a failed episode
    env.close()
    assert not random_episode["next", "success"].any()
    random_episode["embedding"] = embed(random_episode["observation"])
    random_episode["next", "embedding"] = embed(random_episode["next", "observation"])
    buffer.extend(episode_rows(random_episode, embedding_dtype=torch.float32))
    texts = encoder.embed_text(["open a drawer", "robot arm beside table"])
    held_out = embed(experts[3]["next", "observation"])
    before, after = [], []
    for seed in range(4):  # untrained heads order the states by chance, in either direction
        torch.manual_seed(seed)
        reward = TemporalReward(32, texts[0], texts[1], positional="furl", directional=None)
        loss = PositionalRankingLoss(reward, torch.zeros(32), stage=2)
        optimizer = torch.optim.Adam(loss.parameters(), lr=1e-3)
        with torch.no_grad():
            before.append(spearman(reward.positional_reward(held_out)))
        for _ in range(200):
            value = loss(buffer.finetuning.sample(64))["loss_positional"]
            optimizer.zero_grad()
            value.backward()
            optimizer.step()
        with torch.no_grad():
            after.append(spearman(reward.positional_reward(held_out)))
    assert min(after) > 0.9 and min(before) < 0.5, (before, after)
