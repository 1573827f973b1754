"""Metaworld tasks as TorchRL environments (thesis chapter 5: tasks and protocol).

:func:`make_env` builds a :class:`MetaworldEnv`, a small :class:`~torchrl.envs.EnvBase` around
Metaworld's goal-hidden (or goal-observable) task class, optionally followed by a
:class:`~temporal_torchrl.transforms.RenderTransform`.

Why a custom ``EnvBase`` rather than ``GymWrapper``: the wrapper's generic info-dict parsing,
spec conversion and numpy/torch round trips cost about as much as a Metaworld step itself
(about 0.6x the raw env's throughput). Here each step reads only ``info["success"]`` and builds
the output TensorDict directly, which keeps the TorchRL env close to the raw env's speed
(see ``benchmarks/bench_envs.py``).

Episode semantics (the prior implementations' protocol):

- ``goal="fixed"`` (the thesis's protocol): the layout (object and goal positions) is sampled
  once, in the constructor, from ``seed``, and every reset restores it. Different seeds give
  different layouts.
- ``goal="random"`` (Metaworld's benchmark setting, FuRL's, the thesis's section 6 proposal):
  every reset draws a new layout from a generator seeded by ``seed`` and ``stream`` (see
  :func:`layout_generator`), so a run's sequence of layouts is reproducible and the training
  workers, the scripted experts and the evaluation each draw their own. The goal is then
  observable (``observation[36:39]``), as in Metaworld's and FuRL's random-goal tasks: a
  state-based policy cannot otherwise know where the goal is.
- Episodes last ``max_episode_steps`` (500) steps and end by truncation only: a success does
  not terminate the episode.
- ``"success"`` (bool [1]) is Metaworld's per-step success flag ("currently within the
  threshold"); it is False at reset.
- ``"reward"`` is the sparse task reward r_task = success - 1 (0 on success steps, else -1),
  not Metaworld's dense reward.
- ``"observation"`` is Metaworld's 39-d state as float32; its goal dims [36:39] are zero unless
  ``goal_observable=True``.
"""

from __future__ import annotations

import numpy as np
import torch
from metaworld.env_dict import (
    ALL_V3_ENVIRONMENTS_GOAL_HIDDEN,
    ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE,
)
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase, TransformedEnv

from temporal_torchrl import defaults
from temporal_torchrl.envs.tasks import TaskSpec, get_task
from temporal_torchrl.params import EnvParams, env_params

_OBSERVATION_DIM = 39
_ACTION_DIM = 4

#: The independent layout streams of one seed under random goals (``stream``).
LAYOUT_STREAMS = ("training", "experts", "evaluation")


def layout_generator(seed: int, stream: str = "training", index: int = 0) -> np.random.Generator:
    """The generator a random-goal env draws its layouts from.

    One seed has independent streams, so that training (``index``: the worker, each of
    ``env.num_envs`` its own), the scripted experts (``index``: the collection round) and the
    evaluation (held-out layouts) never share layouts by construction. Metaworld's own seeding
    cannot give this: ``reset(seed=...)`` is ignored, and workers forked with ``seed=None`` draw
    the same layouts.
    """
    if stream not in LAYOUT_STREAMS:
        raise ValueError(f"stream={stream!r}; expected one of {LAYOUT_STREAMS}.")
    sequence = np.random.SeedSequence(seed, spawn_key=(LAYOUT_STREAMS.index(stream), index))
    return np.random.Generator(np.random.PCG64(sequence))


class MetaworldEnv(EnvBase):
    """One Metaworld task as a TorchRL environment (no rendering).

    Args:
        task: short task name (``"drawer-open"``) or a :class:`TaskSpec`.
        seed: decides the layout (fixed goal: the same on every reset) or the layouts' stream
            (random goal).
        goal: ``"fixed"`` (one layout, the thesis's protocol) or ``"random"`` (a new layout at
            every reset).
        stream, stream_index: random goals: which of the seed's layout streams the env draws
            from (:func:`layout_generator`); ignored for fixed goals.
        goal_observable: keep the goal position in ``observation[36:39]``; None (default):
            hidden for fixed goals, observable for random goals.
        max_episode_steps: episode length; the last step is truncated.
        device: device of the output tensors.

    The underlying Metaworld env is ``self.metaworld_env``; ``self.model`` and ``self.data`` are
    its MuJoCo model and data (read by :class:`~temporal_torchrl.transforms.RenderTransform`).

    Example:
        >>> from temporal_torchrl.envs.metaworld_env import MetaworldEnv
        >>> env = MetaworldEnv("push", seed=0, max_episode_steps=10)
        >>> env.rollout(20, break_when_any_done=True)["next", "success"].shape
        torch.Size([10, 1])
    """

    def __init__(self, task: str | TaskSpec, seed: int = 0, *, goal: str = defaults.GOAL,
                 stream: str = "training", stream_index: int = 0,
                 goal_observable: bool | None = None,
                 max_episode_steps: int = defaults.MAX_EPISODE_STEPS,
                 device: str | torch.device = "cpu") -> None:
        spec = get_task(task)
        if goal not in defaults.GOALS:
            raise ValueError(
                f"goal={goal!r} is not a goal setting: expected 'fixed' (one layout per run, the "
                "thesis's protocol) or 'random' (a new layout at every reset)."
            )
        if stream not in LAYOUT_STREAMS:
            raise ValueError(f"stream={stream!r}; expected one of {LAYOUT_STREAMS}.")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(
                f"seed={seed!r} is not an integer: the layout of a fixed-goal task is decided by "
                "an integer seed; pass e.g. seed=0."
            )
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int) \
                or max_episode_steps < 1:
            raise ValueError(
                f"max_episode_steps={max_episode_steps!r} is not a positive integer: pass the "
                "episode length in steps, e.g. 500 (Metaworld's default)."
            )
        super().__init__(device=device, batch_size=torch.Size([]))
        self.task = spec
        self.seed = int(seed)
        self.goal, self.stream, self.stream_index = goal, stream, stream_index
        self.goal_observable = goal == "random" if goal_observable is None else goal_observable
        self.max_episode_steps = max_episode_steps
        if self.goal_observable:
            registry, suffix = ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE, "goal-observable"
        else:
            registry, suffix = ALL_V3_ENVIRONMENTS_GOAL_HIDDEN, "goal-hidden"
        # The constructor samples the layout from `seed` and freezes it for every reset;
        # `reset(seed=...)` would be ignored by Metaworld.
        self.metaworld_env = registry[f"{spec.env_id}-{suffix}"](seed=self.seed)
        if goal == "random":
            # Unfrozen, Metaworld draws each reset's layout from `np_random` (seeded_rand_vec;
            # otherwise from the global numpy generator, shared by every env of the process).
            self.metaworld_env._freeze_rand_vec = False
            self.metaworld_env.seeded_rand_vec = True
            self.restart_layouts()
        # An instance attribute shadows the class's 500 and moves the truncation step.
        self.metaworld_env.max_path_length = max_episode_steps
        self._make_specs()

    @property
    def model(self):
        """The MuJoCo ``MjModel`` of the task."""
        return self.metaworld_env.model

    @property
    def data(self):
        """The MuJoCo ``MjData`` of the task (the current simulator state)."""
        return self.metaworld_env.data

    @property
    def goal_position(self) -> np.ndarray:
        """The true goal position of the current layout (also when it is hidden from the
        agent)."""
        return np.asarray(self.metaworld_env._target_pos, dtype=np.float64).copy()

    def restart_layouts(self) -> None:
        """Random goals: draw the next resets' layouts from the start of the env's stream again
        (an evaluation meets the same held-out layouts each time); fixed goals: nothing to do."""
        if self.goal == "random":
            self.metaworld_env.np_random = layout_generator(self.seed, self.stream,
                                                            self.stream_index)

    def _make_specs(self) -> None:
        # Metaworld's observation space says low == high == 0 on the goal dims even when the
        # goal-observable env fills them, so the spec is plain Unbounded.
        self.observation_spec = Composite(
            observation=Unbounded((_OBSERVATION_DIM,), dtype=torch.float32, device=self.device),
            success=Categorical(2, (1,), dtype=torch.bool, device=self.device),
            shape=(),
            device=self.device,
        )
        self.action_spec = Bounded(-1.0, 1.0, (_ACTION_DIM,), dtype=torch.float32,
                                   device=self.device)
        self.reward_spec = Unbounded((1,), dtype=torch.float32, device=self.device)
        flag = Categorical(2, (1,), dtype=torch.bool, device=self.device)
        self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(),
                                   shape=(), device=self.device)

    def _output(self, observation: np.ndarray, success: bool, reward: float | None,
                truncated: bool) -> TensorDictBase:
        # torch.from_numpy is about 3x cheaper than torch.tensor for these tiny arrays, and
        # this runs at every step.
        source = {
            "observation": torch.from_numpy(observation.astype(np.float32)),
            "success": torch.from_numpy(np.array([success])),
            "done": torch.from_numpy(np.array([truncated])),
            "terminated": torch.from_numpy(np.zeros(1, dtype=bool)),
            "truncated": torch.from_numpy(np.array([truncated])),
        }
        if reward is not None:
            source["reward"] = torch.from_numpy(np.array([reward], dtype=np.float32))
        # The tensors are built to the spec above, so the checked constructor is not needed.
        if self.device.type == "cpu":
            return TensorDict._new_unsafe(source, batch_size=torch.Size([]), device=self.device)
        return TensorDict._new_unsafe(source, batch_size=torch.Size([])).to(self.device)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        observation, _ = self.metaworld_env.reset()
        return self._output(observation, False, None, False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action").detach().cpu().numpy()
        observation, _, _, truncated, info = self.metaworld_env.step(action)
        success = bool(info["success"])
        return self._output(observation, success, float(success) - 1.0, bool(truncated))

    def _step_proc_data(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        # `_step` already writes every reward and done key with its spec's shape; TorchRL's
        # generic completion walks the done spec on every step (about a third of a Metaworld
        # step), so it is only kept when type checks are requested.
        if self.run_type_checks:
            return super()._step_proc_data(next_tensordict)
        return next_tensordict

    def rand_action(self, tensordict: TensorDictBase | None = None) -> TensorDictBase:
        """Write a uniform random action in [-1, 1]^4 (what ``rollout`` uses without a policy).

        Same distribution as ``action_spec.rand()``, without the generic spec machinery, which
        costs more than half a Metaworld step.
        """
        if tensordict is None:
            tensordict = TensorDict(batch_size=torch.Size([]), device=self.device)
        action = torch.rand(_ACTION_DIM, device=self.device).mul_(2.0).sub_(1.0)
        tensordict.set("action", action)
        return tensordict

    def _set_seed(self, seed: int | None) -> None:
        # The layouts are decided by the constructor's seed and stream; a later seed only seeds
        # the action spec's sampler used by `rand_step`.
        if seed is not None:
            torch.manual_seed(seed)

    def close(self, *, raise_if_closed: bool = True) -> None:
        self.metaworld_env.close()
        super().close(raise_if_closed=raise_if_closed)


def make_env(env: str | TaskSpec | EnvParams, seed: int | None = None, *, render: bool = False,
             image_size: int | None = None, camera: str | None = None,
             fast_render: bool | None = None, goal: str | None = None,
             max_episode_steps: int | None = None, stream: str = "training",
             stream_index: int = 0, goal_observable: bool | None = None,
             device: str | torch.device = "cpu") -> EnvBase:
    """A Metaworld task as a TorchRL env, optionally rendering ``"pixels"``.

    Args:
        env: the env's :class:`~temporal_torchrl.params.EnvParams`, or its task (a short name,
            see :data:`temporal_torchrl.envs.TASKS`, or its :class:`TaskSpec`) with the other
            settings at their :class:`~temporal_torchrl.params.EnvParams` defaults.
        seed, image_size, camera, fast_render, goal, max_episode_steps: override ``env``'s
            (None: keep it); their meanings are :class:`~temporal_torchrl.params.EnvParams`'s.
            The seed decides the layout, identical on every reset (random goals: the stream of
            layouts drawn at each reset).
        render: append a :class:`~temporal_torchrl.transforms.RenderTransform` writing
            ``"pixels"`` (uint8 [image_size, image_size, 3], upright) at reset and every step.
        stream, stream_index: the random goals' layout stream (:class:`MetaworldEnv`).
        goal_observable: keep the goal in ``observation[36:39]`` (None: hidden for fixed goals,
            observable for random goals).
        device: device of the output tensors.

    Returns:
        A :class:`MetaworldEnv`, wrapped in a :class:`~torchrl.envs.TransformedEnv` when rendering.

    Example:
        >>> from temporal_torchrl.envs import make_env
        >>> from temporal_torchrl.params import EnvParams
        >>> env = make_env(EnvParams("drawer-open", max_episode_steps=5), render=True)
        >>> rollout = env.rollout(5)
        >>> rollout["next", "pixels"].shape, rollout["next", "reward"].unique().tolist()
        (torch.Size([5, 64, 64, 3]), [-1.0])
    """
    params = env_params(env.name if isinstance(env, TaskSpec) else env, seed, image_size=image_size,
                        camera=camera, fast_render=fast_render, goal=goal,
                        max_episode_steps=max_episode_steps)
    if render:
        # Imported on use: the transforms package also loads the encoders, which a state-only
        # env does not need.
        from temporal_torchrl.transforms.render import RenderTransform

        # Built first so that a bad image size is refused before the simulator is built.
        transform = RenderTransform(**params.render_settings)
    task_env = MetaworldEnv(params.task, params.seed, goal=params.goal, stream=stream,
                            stream_index=stream_index, goal_observable=goal_observable,
                            max_episode_steps=params.max_episode_steps, device=device)
    if not render:
        return task_env
    transform.validate_camera(task_env.model)
    return TransformedEnv(task_env, transform)
