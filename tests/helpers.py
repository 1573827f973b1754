"""Helpers the test files share: tiny recipe configs, the one factory of synthetic episodes,
and waits that fail the test, naming what did not happen, instead of hanging or carrying on."""

import csv
import functools
import json
import os
import select
import signal
import time
from collections.abc import Callable
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from tensordict import TensorDict

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
EXAMPLES = RECIPES.parent / "examples"
D = 4
OBSERVATION_SIZE, ACTION_SIZE = 39, 4  # Metaworld's

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


# --------------------------------------------------------------------------- synthetic episodes
def synthetic_episode(embeddings: torch.Tensor, next_success=None,
                      observations: torch.Tensor | None = None,
                      actions: torch.Tensor | None = None) -> TensorDict:
    """An episode in ``env.rollout()`` layout ``[T]`` through the states s_0 .. s_T.

    Args:
        embeddings: s_0 .. s_T, ``[T + 1, D]``: ``"embedding"`` is s_t, ``("next",
            "embedding")`` s_(t+1).
        next_success: ``("next", "success")`` of the T transitions (the success of s_1 .. s_T;
            s_0 never succeeds), ``[T]`` booleans; default never.
        observations: the observations of s_0 .. s_T ``[T + 1, 39]``; default zeros.
        actions: ``[T, 4]``; default uniform in [0, 1) from torch's generator.
    """
    steps = embeddings.shape[0] - 1
    success = torch.zeros(steps + 1, 1, dtype=torch.bool)
    if next_success is not None:
        success[1:] = torch.as_tensor(next_success, dtype=torch.bool).reshape(steps, 1)
    if observations is None:
        observations = torch.zeros(steps + 1, OBSERVATION_SIZE)
    return TensorDict({
        "observation": observations[:-1].clone(),
        "embedding": embeddings[:-1].clone(),
        "action": torch.rand(steps, ACTION_SIZE) if actions is None else actions,
        "success": success[:-1],
        "next": {"observation": observations[1:].clone(),
                 "embedding": embeddings[1:].clone(),
                 "success": success[1:],
                 "terminated": torch.zeros(steps, 1, dtype=torch.bool)},
    }, [steps])


def make_episode(number: int, steps: int, successes=(), dim: int = D) -> TensorDict:
    """An episode whose state t has embedding and observation all equal to 100 * number + t
    (see :func:`marker`), successful after the transitions ``successes``."""
    states = (100.0 * number + torch.arange(steps + 1, dtype=torch.float32)).unsqueeze(-1)
    next_success = torch.zeros(steps, dtype=torch.bool)
    next_success[list(successes)] = True
    return synthetic_episode(states.expand(-1, dim), next_success,
                   observations=states.expand(-1, OBSERVATION_SIZE))


def marker(values: torch.Tensor) -> torch.Tensor:
    return values[..., 0]


def insert(buffer: EpisodeReplayBuffer, number: int, steps: int, successes=(), **kwargs):
    """Insert make_episode(number, steps, successes) into ``buffer``; returns its rows."""
    return buffer.extend(episode_rows(make_episode(number, steps, successes, **kwargs)))


# --------------------------------------------------------------------------- waits that fail
class WaitTimeout(AssertionError):
    """A wait of a test ran out: what it waited for did not happen (a failure, not a hang)."""


def wait_until(condition: Callable[[], bool], timeout: float, what: str,
               interval: float = 0.05, alive: Callable[[], str | None] | None = None) -> None:
    """Poll ``condition`` until it holds; fail naming ``what`` after ``timeout`` seconds, or as
    soon as ``alive()`` returns why the process that should make it hold is gone."""
    deadline = time.monotonic() + timeout
    while not condition():
        gone = alive() if alive is not None else None
        if gone is not None:
            raise WaitTimeout(f"{what}: never happened, {gone}")
        if time.monotonic() > deadline:
            raise WaitTimeout(f"{what}: not within {timeout:.0f} s")
        time.sleep(interval)


def recorded_episodes(run_dir: Path) -> int:
    """How many episode rows the run's episodes.csv holds (0 before it exists)."""
    path = Path(run_dir) / "episodes.csv"
    if not path.exists():
        return 0
    with path.open() as file:
        return sum(1 for line in file.read().splitlines()[1:] if line.strip())


def wait_for_episode(run_dir: Path, episode: int, timeout: float,
                     alive: Callable[[], str | None] | None = None) -> None:
    """Wait until the run in ``run_dir`` has reported ``episode`` in its episodes.csv (the row
    is written just before that episode's checkpoint): the deterministic point to kill it."""
    wait_until(lambda: recorded_episodes(run_dir) >= episode, timeout,
               f"the run in {run_dir} reporting episode {episode} in episodes.csv",
               alive=alive)


def popen_alive(process) -> Callable[[], str | None]:
    """For :func:`wait_until`: why a ``subprocess.Popen`` is gone, None while it runs."""
    return lambda: (None if process.poll() is None
                    else f"the process exited with code {process.returncode}")


def read_from_child(fd: int, pid: int, size: int, timeout: float, what: str) -> bytes:
    """What the forked child ``pid`` writes to the pipe ``fd`` (its write end closed in this
    process): fails naming ``what`` when the child exits without writing (end of file) or
    writes nothing within ``timeout`` seconds, and then kills the child rather than hang."""
    ready, _, _ = select.select([fd], [], [], timeout)
    data = os.read(fd, size) if ready else None
    if data:
        return data
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    _, status = os.waitpid(pid, 0)
    if data is None:
        raise WaitTimeout(f"{what}: the forked child (pid {pid}) wrote nothing within "
                          f"{timeout:.0f} s (killed)")
    raise WaitTimeout(f"{what}: the forked child (pid {pid}) exited without it "
                      f"(wait status {status})")


def make_checkpoint(**fields):
    """A :class:`~temporal_torchrl.runs.Checkpoint` with ``fields`` and empty or zero values
    for the rest (for tests of the run's files, which do not read the modules' states)."""
    from temporal_torchrl.runs import Checkpoint

    defaults = {"episode": 0, "env_steps": 0, "inserted": 0, "updates": 0, "successes": [],
                "last_metrics": {}, "sac_loss": {}, "sac_optimizer": {}, "reward": {},
                "trainer": {}, "relay": {}, "goal_image": None, "buffer_capacity": 0,
                "expert_rows": 0, "preloaded": 0, "rng": {}}
    return Checkpoint(**(defaults | fields))


def error_chain(error: BaseException | None) -> str:
    """An error's message and its causes'."""
    messages = []
    while error is not None:
        messages.append(str(error))
        error = error.__cause__
    return "\n".join(messages)


# --------------------------------------------------------------------------- run directories
# seed 0: 150 failures then 150 successes -> RAS(300; 150) = 100 %, TTFS 151, TT50S 200.
SEED0 = [False] * 150 + [True] * 150
# seed 1: 160 failures then success, failure, ... -> 70 of episodes 151..300: RAS 46.67 %,
# TTFS 161, TT50S 161 + 2 * 49 = 259.
SEED1 = [False] * 160 + [True, False] * 70


@functools.cache
def _composed(overrides: tuple[str, ...]) -> str:
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("config", overrides=list(overrides))
    return json.dumps(OmegaConf.to_container(cfg, resolve=True))


def make_run(root: Path, name: str, successes, *overrides: str, finished: bool = False,
             logged: dict | None = None) -> Path:
    """A run directory as the recipe writes it: config.json, episodes.csv, summary.json when
    ``finished``, CSV logs of ``logged`` ({key: [(step, value)]})."""
    run_dir = root / name
    run_dir.mkdir(parents=True)
    config = json.loads(_composed(tuple(overrides)))
    config["output_dir"] = str(run_dir)
    (run_dir / "config.json").write_text(json.dumps(config))
    with (run_dir / "episodes.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["episode", "env_steps", "success", "return", "mean_vlm_reward",
                         "stage"])
        for episode, success in enumerate(successes, start=1):
            writer.writerow([episode, 500 * episode, int(success), -500 + int(success), 0.0, 2])
    if finished:
        (run_dir / "summary.json").write_text(json.dumps({"episodes": len(successes)}))
    for key, points in (logged or {}).items():
        path = run_dir / "logs" / run_dir.name / "scalars" / f"{key}.csv"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(f"{step},{value}\n" for step, value in points))
    return run_dir
