"""FuRL's relay exploration, as the thesis release runs it.

Until the finetuning has enough positive states, each training episode alternates between the
VLM-reward agent and a *relay* agent: a second SAC agent trained on the sparse task reward only,
whose sampled actions get Gaussian noise. The thesis release (``train_furl.py`` in
LukasWill/directional_vlm_rl, after FuRL's fuyw/FuRL) does this:

- within an episode the agent acting at step ``t`` is ``agents[(t // period) % 2]``, with
  ``period`` drawn uniformly from ``(50, 100, 150, 200)`` at the start of every episode;
- ``agents`` starts as ``(vlm, relay)`` and is reversed at every episode end, warm-up episodes
  included, so episode ``e`` (0-based, counted from the run's start) opens with the VLM agent
  when ``e`` is even;
- the relay agent's action is its policy's sample plus ``N(0, (noise * max_action)^2)``, clipped
  to the action bounds (``noise = 0.2``);
- at an episode end, once the positive embedding buffer holds ``threshold = 2500`` states, relay
  stops for good; the relay agent is updated on the VLM agent's batches (with their sparse task
  reward) while relay is on.

With stage 2's 50 preloaded positives the threshold is met before the first episode, so relay
never acts there (the release's first episode end, inside the warm-up, switches it off); it
shapes stage 1, where the first successes are found. Here relay is off from the start when the
preloaded positives already meet the threshold, which is the release's behaviour whenever the
warm-up is at least one episode long.

:class:`RelaySchedule` holds the per-env episode clock and the period draws (its own generator,
so a run's other random streams are the same with relay on or off); :class:`RelayPolicy` is the
collector's policy, choosing per env between the two actors.

Example:
    >>> from temporal_torchrl.params import RelayParams
    >>> schedule = RelaySchedule(1, RelayParams(periods=[2], threshold=10), seed=0)
    >>> masks = []
    >>> for _ in range(5):
    ...     masks.append(bool(schedule.relay_mask()[0]))
    ...     schedule.advance(ended=[])
    >>> masks  # VLM for 2 steps, relay for 2, VLM again
    [False, False, True, True, False]
    >>> schedule.advance(ended=[0])  # the next episode opens with the relay agent
    >>> bool(schedule.relay_mask()[0])
    True
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import TensorSpec

from temporal_torchrl.params import RelayParams


class RelaySchedule:
    """Which agent acts in each env at the current step (see the module doc).

    Args:
        num_envs: envs stepped together (each has its own episode clock).
        params: the switching periods one is drawn from per episode, the positive states at
            which relay ends (:meth:`end_if_enough`) and the relay agent's action noise
            (:class:`RelayPolicy`); None: the release's
            (:class:`~temporal_torchrl.params.RelayParams`' defaults).
        seed: seed of the schedule's own generator (the period draws).
        active: False when relay is off from the start.
    """

    def __init__(self, num_envs: int, params: RelayParams | None = None, *, seed: int = 0,
                 active: bool = True) -> None:
        self.params = RelayParams() if params is None else params
        self.periods = torch.tensor(self.params.periods)
        self.threshold = self.params.threshold
        self.active = active
        self.generator = torch.Generator().manual_seed(seed)
        self.step = torch.zeros(num_envs, dtype=torch.long)
        self.episode = torch.zeros(num_envs, dtype=torch.long)
        self.period = self._draw(num_envs)
        self.relay_steps = torch.zeros(num_envs, dtype=torch.long)
        self.total_relay_steps = 0

    def _draw(self, count: int) -> torch.Tensor:
        return self.periods[torch.randint(len(self.periods), (count,), generator=self.generator)]

    def relay_mask(self) -> torch.Tensor:
        """Per env: whether the relay agent takes the current step (all False once inactive)."""
        if not self.active:
            return torch.zeros_like(self.step, dtype=torch.bool)
        return (self.step // self.period + self.episode) % 2 == 1

    def advance(self, ended: Sequence[int], acted: bool = True) -> None:
        """One vector step taken (``acted``: by the policy, not the warm-up's random actions);
        the envs in ``ended`` start their next episode."""
        if acted:
            relay = self.relay_mask().long()
            self.relay_steps += relay
            self.total_relay_steps += int(relay.sum())
        self.step += 1
        if ended:
            index = torch.as_tensor(list(ended), dtype=torch.long)
            self.step[index] = 0
            self.episode[index] += 1
            self.period[index] = self._draw(len(index))

    def episode_relay_steps(self, env: int) -> int:
        """The relay steps of ``env``'s episode that just ended, and its counter reset."""
        steps = int(self.relay_steps[env])
        self.relay_steps[env] = 0
        return steps

    def end_if_enough(self, positive_states: int) -> None:
        """Relay stops for good once the finetuning holds ``threshold`` positive states."""
        if self.active and positive_states >= self.threshold:
            self.active = False

    def state_dict(self) -> dict[str, Any]:
        return {"active": self.active, "generator": self.generator.get_state(),
                "step": self.step.clone(), "episode": self.episode.clone(),
                "period": self.period.clone(), "relay_steps": self.relay_steps.clone(),
                "total_relay_steps": self.total_relay_steps}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.active = bool(state["active"])
        self.generator.set_state(state["generator"])
        self.total_relay_steps = int(state["total_relay_steps"])
        for key in ("step", "episode", "period", "relay_steps"):
            getattr(self, key).copy_(state[key])


class RelayPolicy(TensorDictModuleBase):
    """The collector's policy while relay may act: ``actor``'s action, replaced in the envs the
    ``schedule`` gives to the relay agent by ``relay_actor``'s sample plus Gaussian noise
    (the schedule's ``params.noise`` times the action bound), clipped to ``action_spec``'s
    bounds.

    Once the schedule is inactive it is ``actor`` alone, drawing the same random numbers.
    """

    def __init__(self, actor: TensorDictModuleBase, relay_actor: TensorDictModuleBase,
                 schedule: RelaySchedule, action_spec: TensorSpec) -> None:
        super().__init__()
        self.actor = actor
        self.relay_actor = relay_actor
        self.schedule = schedule
        self.noise = schedule.params.noise
        self.in_keys = list(actor.in_keys)
        self.out_keys = list(actor.out_keys)
        self.register_buffer("low", action_spec.space.low.clone())
        self.register_buffer("high", action_spec.space.high.clone())

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        mask = self.schedule.relay_mask()
        tensordict = self.actor(tensordict)
        if not bool(mask.any()):
            return tensordict
        relay = self.relay_actor(tensordict.select(*self.relay_actor.in_keys).clone(False))
        action = relay["action"]
        # The release scales the noise by max_action: Metaworld's bounds are symmetric.
        action = action + self.noise * self.high * torch.randn_like(action)
        action = torch.maximum(torch.minimum(action, self.high), self.low)
        mask = mask.to(action.device).reshape(*tensordict.batch_size, 1)
        tensordict["action"] = torch.where(mask, action, tensordict["action"])
        return tensordict


class RelayExploration:
    """The relay agent of a run: its collector policy (:class:`RelayPolicy` and its schedule),
    its SAC loss and optimizer, and its update, which it takes on the VLM agent's batches with
    their sparse task reward ``success - 1`` (the release's ``sac_agent.update(batch)``)."""

    def __init__(self, policy: RelayPolicy, loss: torch.nn.Module,
                 optimizer: torch.optim.Optimizer,
                 update: Callable[[TensorDictBase], TensorDictBase]) -> None:
        self.policy = policy
        self.loss = loss
        self.optimizer = optimizer
        #: One SAC step of the relay agent on a :meth:`task_reward_batch`.
        self.update = update

    @property
    def schedule(self) -> RelaySchedule:
        return self.policy.schedule

    @property
    def total_steps(self) -> int:
        """Env steps the relay agent has acted in."""
        return self.schedule.total_relay_steps

    @staticmethod
    def task_reward_batch(batch: TensorDictBase) -> TensorDictBase:
        """``batch`` (a shallow copy) with the sparse task reward instead of the relabelled one;
        take it before the VLM agent's update, which may add keys to ``batch``."""
        relay_batch = batch.clone(False)
        relay_batch["next", "reward"] = batch["next", "success"].float() - 1.0
        return relay_batch

    def batch_to_learn(self, batch: TensorDictBase) -> TensorDictBase | None:
        """What the relay agent learns from ``batch`` (:meth:`task_reward_batch`), None once the
        relay has ended."""
        return self.task_reward_batch(batch) if self.schedule.active else None

    def episode_metrics(self, env: int, length: int) -> dict[str, float]:
        """The logged share of env ``env``'s ended episode (``length`` steps) the relay acted."""
        return {"train/relay_fraction": self.schedule.episode_relay_steps(env) / length}

    def advance(self, ended: Sequence[int], acted: bool) -> None:
        """One vector step taken (:meth:`RelaySchedule.advance`)."""
        self.schedule.advance(ended, acted=acted)

    def end_if_enough(self, positive_states: int) -> None:
        self.schedule.end_if_enough(positive_states)

    def state_dict(self) -> dict[str, Any]:
        return {"schedule": self.schedule.state_dict(), "loss": self.loss.state_dict(),
                "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.schedule.load_state_dict(state["schedule"])
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])


class NoRelay:
    """A run without relay exploration, with :class:`RelayExploration`'s interface: the actor
    collects alone, nothing is learned or logged, nothing is saved. ``reason`` says why."""

    total_steps = 0

    def __init__(self, actor: TensorDictModuleBase, reason: str) -> None:
        self.policy = actor
        self.reason = reason

    def batch_to_learn(self, batch: TensorDictBase) -> None:
        return None

    def episode_metrics(self, env: int, length: int) -> dict[str, float]:
        return {}

    def advance(self, ended: Sequence[int], acted: bool) -> None:
        pass

    def end_if_enough(self, positive_states: int) -> None:
        pass

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        pass
