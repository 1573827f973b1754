"""Helpers the test files share: tiny recipe configs and hand-made episodes with known values."""

import csv
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
D = 4

# Tiny but complete: 20-step episodes, updates from step 11 on, small networks and batches.
QUICK = [
    "env.max_episode_steps=20", "train.episodes=3", "train.random_steps=10",
    "encoder.name=state", "+encoder.options.dim=16", "sac.batch_size=16",
    "sac.hidden_sizes=[32,32]", "reward.batch_size=16", "reward.gap=3", "logger.backend=none",
    "train.progress=false",
]


def config(tmp_path, *overrides):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("config", overrides=[*QUICK, f"output_dir={tmp_path / 'run'}",
                                             *overrides])


def episode_csv_rows(run_dir: Path) -> list[dict]:
    with (run_dir / "episodes.csv").open() as file:
        return list(csv.DictReader(file))


def make_episode(episode: int, steps: int, successes=(), dim: int = D) -> TensorDict:
    """An episode whose state t has embedding and observation all equal to 100 * episode + t."""
    states = (100.0 * episode + torch.arange(steps + 1, dtype=torch.float32)).unsqueeze(-1)
    success = torch.zeros(steps + 1, 1, dtype=torch.bool)
    for t in successes:  # success after transition t
        success[t + 1] = True
    return TensorDict({
        "observation": states.expand(-1, 39)[:-1].clone(),
        "embedding": states.expand(-1, dim)[:-1].clone(),
        "action": torch.rand(steps, 4),
        "success": success[:-1],
        "next": {"observation": states.expand(-1, 39)[1:].clone(),
                 "embedding": states.expand(-1, dim)[1:].clone(),
                 "success": success[1:],
                 "terminated": torch.zeros(steps, 1, dtype=torch.bool)},
    }, [steps])


def marker(values: torch.Tensor) -> torch.Tensor:
    return values[..., 0]


def insert(buffer: EpisodeReplayBuffer, episode: int, steps: int, successes=(), **kwargs):
    """Insert make_episode(episode, steps, successes) into ``buffer``; returns its rows."""
    return buffer.extend(episode_rows(make_episode(episode, steps, successes, **kwargs)))
