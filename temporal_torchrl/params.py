"""The components' parameter objects: one small, torch-free dataclass per component, which the
library's constructors take and the recipes' config schemas nest (BenchMARL's manner).

- :class:`EnvParams`: the task's env and its frames (``env.*``), taken by
  :func:`~temporal_torchrl.envs.make_env`, :func:`~temporal_torchrl.envs.make_temporal_env`,
  the scripted experts and the evaluation;
- :class:`EvalParams`: the evaluation episodes (``eval.*``);
- :class:`RelayParams`: FuRL's relay exploration (``train.relay_periods``, ``relay_noise``,
  ``relay_threshold``), taken by :class:`~temporal_torchrl.training.relay.RelaySchedule` and
  :class:`~temporal_torchrl.training.relay.RelayPolicy`;
- :class:`DatasetParams`: the offline reward-quality benchmark's episodes (``dataset.*``),
  part of :class:`~temporal_torchrl.reward_quality.DatasetSpec`.

Each field's default is written here once (its value read from :mod:`temporal_torchrl.defaults`)
with its range (:func:`~temporal_torchrl.fields.constrained`), which a config's keys and
an object built in code are both checked against: ``EnvParams(image_size=0)`` is refused as
``env.image_size=0`` is. The recipes build them from their sections
(``EnvParams.from_section(cfg.env)``, :meth:`Params.from_section`). The history's k and
window have one route, the reward's
(:class:`~temporal_torchrl.rewards.TemporalReward`'s ``k`` and ``window_length``).

Example:
    >>> from temporal_torchrl.params import EnvParams
    >>> params = EnvParams("door-open", seed=3)
    >>> params.image_size, params.camera, params.max_episode_steps, params.goal
    (64, 'corner2', 500, 'fixed')
    >>> params.replace(max_episode_steps=20).max_episode_steps
    20
    >>> EnvParams(image_size=0)
    Traceback (most recent call last):
    ...
    ValueError: EnvParams: image_size=0; expected an integer >= 1.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Self

from temporal_torchrl import defaults
from temporal_torchrl.fields import check_fields, constrained


class Params:
    """What every parameter object does: check its fields when built, build from a config
    section, copy with changes."""

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def from_section(cls, section: Mapping[str, Any]) -> Self:
        """The object of a config section that holds its fields among others (a recipe's
        ``env``: ``EnvParams.from_section(cfg.env)``)."""
        return cls(**{spec.name: section[spec.name] for spec in dataclasses.fields(cls)})

    def replace(self, **changes: Any) -> Self:
        """A copy with ``changes`` (checked as the constructor checks); a ``None`` change keeps
        the field, so a function's unset keyword overrides nothing."""
        return dataclasses.replace(self, **{name: value for name, value in changes.items()
                                            if value is not None})


@dataclass
class EnvParams(Params):
    """A Metaworld task's env: its layout, episode length, goal setting and rendered frames
    (``env.*`` of both recipes)."""

    #: Any Metaworld MT50 short name; the thesis evaluates six.
    task: str = "drawer-open"
    #: The layout (fixed goal) and every random generator of the run.
    seed: int = constrained(0, ge=0)
    #: Steps per episode (Metaworld's truncation).
    max_episode_steps: int = constrained(defaults.MAX_EPISODE_STEPS, ge=1)
    #: Side of the rendered frames (square); only encoders that read pixels use them.
    image_size: int = constrained(defaults.IMAGE_SIZE, ge=1)
    #: The Metaworld camera rendered.
    camera: str = defaults.CAMERA
    #: Shadows, reflections and MSAA off (about 8x faster on a CPU); false: Metaworld's look.
    fast_render: bool = defaults.FAST_RENDER
    #: fixed: one layout per run, from seed (the thesis) | random: a new layout at every
    #: reset, from a stream seeded by seed (the goal then observable).
    goal: str = constrained(defaults.GOAL, choices=defaults.GOALS)

    @property
    def render_settings(self) -> dict[str, Any]:
        """The render transform's keywords for these frames."""
        return {"camera": self.camera, "image_size": self.image_size, "fast": self.fast_render}


def env_params(env: str | EnvParams, seed: int | None = None, **changes: Any) -> EnvParams:
    """``env`` as an :class:`EnvParams` (a task name: its defaults), with ``seed`` and
    ``changes`` applied where not ``None``: what the library's env functions do with their
    first argument and keywords."""
    params = env if isinstance(env, EnvParams) else EnvParams(task=env)
    return params.replace(seed=seed, **changes)


@dataclass
class EvalParams(Params):
    """Evaluation episodes of the deterministic policy, apart from training (``eval.*``; none
    in the thesis's protocol)."""

    #: Evaluate after every this many training episodes (null: never).
    every: int | None = constrained(None, ge=1)
    #: Episodes per evaluation: random goals, each on its own held-out layout (the same ones at
    #: every evaluation); fixed goals, on the run's layout.
    episodes: int = constrained(defaults.EVAL_EPISODES, ge=1)


@dataclass
class RelayParams(Params):
    """FuRL's relay exploration (the thesis release's values): the recipe's
    ``train.relay_periods``, ``train.relay_noise`` and ``train.relay_threshold``."""

    #: Switch agents every period steps, one period drawn per episode.
    periods: list[int] = constrained(list(defaults.RELAY_PERIODS), ge=1, nonempty=True)
    #: Gaussian noise on the relay agent's actions, times the action bound.
    noise: float = constrained(defaults.RELAY_NOISE, ge=0)
    #: Positive states that end relay (protocol stage 2's 50 preloaded: it never starts).
    threshold: int = constrained(defaults.RELAY_THRESHOLD, ge=0)

    def __post_init__(self) -> None:
        self.periods = list(self.periods)
        super().__post_init__()


@dataclass
class DatasetParams(Params):
    """The offline reward-quality benchmark's episodes, besides the env's settings
    (``dataset.*``)."""

    #: Successful scripted-expert episodes (the positives).
    expert_episodes: int = constrained(defaults.DATASET_EXPERT_EPISODES, ge=2)
    #: Failed episodes of uniform random actions.
    random_episodes: int = constrained(defaults.DATASET_RANDOM_EPISODES, ge=0)
    #: Failed episodes of the expert with a large action noise.
    failed_expert_episodes: int = constrained(defaults.DATASET_FAILED_EXPERT_EPISODES, ge=0)
    #: The successful experts' action noise (the stage-2 preloaded positives').
    expert_noise: float = constrained(defaults.EXPERT_NOISE, ge=0)
    #: Experts are cut this many steps after their first success (null: whole episodes), as
    #: ``train.expert_steps_after_success``.
    expert_steps_after_success: int | None = constrained(defaults.EXPERT_STEPS_AFTER_SUCCESS,
                                                         ge=0)
    #: The failed experts' noise; doubled while most of their episodes still succeed.
    failure_noise: float = constrained(defaults.DATASET_FAILURE_NOISE, gt=0)
    #: Episodes tried per episode wanted, for each kind, before giving up.
    max_attempts: int = constrained(defaults.DATASET_MAX_ATTEMPTS, ge=1)
