"""What the sections share: their budgets, the recipe's config and parts, and its loop timed.

The updates and the step are measured on the recipe's own parts, built by its factories for the
state encoder on a buffer of synthetic episodes (:func:`training_setup`); the loops are the
recipe's ``train`` itself, timed at the episode ends it reports through its ``on_episode_end``
hook (:func:`steady_steps_per_second`).
"""

from __future__ import annotations

import inspect
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import sac_temporal
import torch
from _common import seconds_per_call
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig
from tensordict import TensorDict

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.data import episode_rows
from temporal_torchrl.training import factories
from training import RECIPES

RUN_IDS = itertools.count()  # a fresh output_dir per recipe run
OBSERVATION_DIM, ACTION_DIM = 39, 4  # Metaworld's state and action


@dataclass(frozen=True)
class Budget:
    """How long and how large the sections measure: :data:`FULL`, :data:`QUICK` (``--quick``)
    or :data:`SMOKE` (``--smoke``: sizes that only check that every section runs and gives its
    rows, for the tests; its figures mean nothing)."""

    #: ``full``, ``quick`` or ``smoke``: the command-line flag (``--quick``, ``--smoke``).
    name: str
    #: The timing window of one update, step or sampling measurement (seconds).
    seconds: float
    #: Alternating rounds of the SAC update's and d_sequence's head-update timings.
    rounds: int
    #: Fresh-process runs of the default loop, eager and compiled (and another revision's).
    loop_rounds: int
    #: Env steps of a loop episode; LIV's, in the grid, at 224 px.
    episode_length: int
    liv_episode_length: int
    #: The grid's ``env.num_envs``.
    num_envs: tuple[int, ...]
    #: Episodes of the plain TorchRL loop and the recipe beside it, and their length.
    plain_loop_episodes: int
    plain_loop_length: int
    #: Transitions in the replay section's buffers.
    replay_transitions: int
    #: Synthetic episodes (and their length) in the buffer of the updates and the step.
    buffer_episodes: int
    buffer_episode_length: int
    #: The grid's GPU row (LIV, 16 envs, everything on the GPU) when CUDA is there.
    gpu_rows: bool
    #: The grid's encoders (``encoder.name``).
    grid_encoders: tuple[str, ...] = ("state", "metaworld_small", "liv")
    #: Calls before each timing window.
    warmup_calls: int = 5
    #: The default loop's rates each in a fresh process (else in this one).
    fresh_processes: bool = True
    #: Overrides of every recipe config the sections build (smoke: smaller networks, batches).
    overrides: tuple[str, ...] = ()

    def seconds_per_call(self, fn: Callable[[], object], fraction: float = 1.0) -> float:
        """Mean seconds of one call of ``fn``, timed over ``fraction`` of the timing window
        after the budget's warm-up calls."""
        return seconds_per_call(fn, min_seconds=fraction * self.seconds,
                                warmup_calls=self.warmup_calls)


FULL = Budget(name="full", seconds=4.0, rounds=5, loop_rounds=3, episode_length=100,
              liv_episode_length=24, num_envs=(1, 2, 4), plain_loop_episodes=4,
              plain_loop_length=250, replay_transitions=500_000, buffer_episodes=10,
              buffer_episode_length=500, gpu_rows=True)
QUICK = Budget(name="quick", seconds=1.0, rounds=2, loop_rounds=3, episode_length=20,
               liv_episode_length=8, num_envs=(1, 2), plain_loop_episodes=3,
               plain_loop_length=100, replay_transitions=500_000, buffer_episodes=10,
               buffer_episode_length=500, gpu_rows=False)
SMOKE = Budget(name="smoke", seconds=0.02, rounds=1, loop_rounds=1, episode_length=4,
               liv_episode_length=2, num_envs=(1,), plain_loop_episodes=2,
               plain_loop_length=10, replay_transitions=4_000, buffer_episodes=3,
               buffer_episode_length=100, gpu_rows=False, grid_encoders=("state",),
               warmup_calls=1, fresh_processes=False,
               overrides=("sac.hidden_sizes=[32,32]", "sac.batch_size=16",
                          "reward.batch_size=16"))
BUDGETS = {budget.name: budget for budget in (FULL, QUICK, SMOKE)}


def recipe_config(output_dir: Path, budget: Budget, *overrides: str) -> DictConfig:
    """The recipe's config for a benchmark run: no logger, no progress bar, no random warm-up,
    FuRL + D3 (rho 1, lambda 4) on the CPU, the scripted expert that gives the goal image cut
    after its first success (the goal is that state; the rest would only lengthen the start-up,
    which no row times), then ``budget.overrides`` and ``overrides``."""
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("config", overrides=[
            f"output_dir={output_dir}", "logger.backend=none", "train.progress=false",
            "train.random_steps=0", "reward.positional=furl", "reward.directional=d3",
            "reward.lambda_=4.0", "reward.rho=1.0", "train.device=cpu",
            "train.expert_steps_after_success=1", *budget.overrides, *overrides])


def synthetic_episode(length: int, dim: int, success_from: int | None = None) -> TensorDict:
    """An episode of random states, embeddings and actions, successful from ``success_from``."""
    embedding = torch.randn(length + 1, dim)
    observation = torch.randn(length + 1, OBSERVATION_DIM)
    success = torch.zeros(length + 1, 1, dtype=torch.bool)
    if success_from is not None:
        success[success_from:] = True
    return TensorDict({
        "observation": observation[:-1], "embedding": embedding[:-1],
        "action": torch.rand(length, ACTION_DIM) * 2 - 1, "success": success[:-1],
        "next": {"observation": observation[1:], "embedding": embedding[1:],
                 "success": success[1:],
                 "terminated": torch.zeros(length, 1, dtype=torch.bool)}}, [length])


def training_setup(tmp: Path, budget: Budget, dim: int, *overrides: str,
                   stage: int = 2) -> dict:
    """The recipe's reward, buffer (``budget.buffer_episodes`` synthetic episodes, the first
    successful from 3/5 of its length in ``stage`` 2), reward-head trainer and SAC update, built
    by its factories for the state encoder at D = ``dim``: a dict of ``cfg``, ``buffer``,
    ``trainer``, ``actor``, ``loss`` and ``update_sac``."""
    cfg = recipe_config(tmp / f"setup_{next(RUN_IDS)}", budget, "encoder.name=state",
                        f"+encoder.options.dim={dim}", *overrides)
    torch.manual_seed(0)
    devices = Devices.of(cfg)
    reward = factories.make_reward(cfg, factories.make_encoder(cfg, devices.encoder), devices)
    env = factories.make_environment(cfg, None, None)
    actor, critics = factories.make_sac_agent(cfg, env, devices)
    env.close()
    loss, optimizer = factories.make_sac_loss(cfg, actor, critics, ACTION_DIM)
    length = budget.buffer_episode_length
    buffer = factories.make_replay_buffer(cfg, 2 * budget.buffer_episodes * (length + 1),
                                          reward, devices)
    buffer.extend(episode_rows(synthetic_episode(
        length, dim, success_from=3 * length // 5 if stage == 2 else None)))
    for _ in range(budget.buffer_episodes - 1):
        buffer.extend(episode_rows(synthetic_episode(length, dim)))
    trainer = factories.make_reward_trainer(cfg, reward, torch.randn(dim), buffer)
    assert trainer.stage == stage
    return {"cfg": cfg, "buffer": buffer, "trainer": trainer, "actor": actor, "loss": loss,
            "update_sac": factories.make_sac_update(cfg, loss, optimizer)}


def steady_steps_per_second(cfg_overrides: list[str], num_envs: int, length: int,
                            tmp: Path, budget: Budget) -> float:
    """Env steps/s over the 3rd and 4th rounds of ``num_envs`` episodes of ``length`` steps in
    one run of the recipe, timed at the episode ends it reports (``on_episode_end``): the first
    round has no updates, the second compiles."""
    if "on_episode_end" not in inspect.signature(sac_temporal.train).parameters:
        raise SystemExit(f"{Path(sac_temporal.__file__)}: its train() has no on_episode_end "
                         "hook, which the loops are timed with; measure a revision that has it.")
    clock: dict[int, float] = {}

    def episode_ended(episode: int, env_steps: int) -> None:
        clock[env_steps] = time.perf_counter()

    cfg = recipe_config(tmp / f"loop_{next(RUN_IDS)}", budget, *cfg_overrides,
                        f"env.num_envs={num_envs}", f"env.max_episode_steps={length}",
                        f"train.episodes={4 * num_envs}")
    sac_temporal.train(cfg, on_episode_end=episode_ended)
    second, fourth = 2 * num_envs * length, 4 * num_envs * length
    return (fourth - second) / (clock[fourth] - clock[second])
