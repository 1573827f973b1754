"""The temporal reward as a TorchRL transform, in the env and on sampled batches."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl import timeit
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from temporal_torchrl.rewards.temporal import REWARD_KEYS, TemporalReward
from temporal_torchrl.transforms.history import WINDOW_KEY

INPUT_KEYS = ("embedding", "initial_embedding", "previous_embedding", "success")


#: The shaped reward's parts, written beside it as observations (the env's reward is "reward").
COMPONENT_KEYS = tuple(key for key in REWARD_KEYS if key != "reward")
#: Where the referenced reward's state sits in the transform's (and so the env's) state_dict.
REWARD_PREFIX = "reward."


class TemporalRewardTransform(Transform):
    """Overwrites ``"reward"`` with r = r_task + rho (r_P + lambda r_D) (thesis 4.1).

    Reads ``"embedding"`` (s_{t+1}), ``"initial_embedding"``, ``"previous_embedding"`` and
    ``"success"`` of the *next* state (and ``"embedding_window"`` when the reward reads a window,
    ``reward.window_length`` not None) and writes ``"task_reward"``, ``"positional_reward"``,
    ``"directional_reward"``, ``"vlm_reward"`` and ``"reward"`` (all float32 ``[..., 1]``), with
    the heads as they are now and without gradient. ``"reward"``, the shaped reward the agent
    trains on, is the env's one reward key, as TorchRL's loss modules, collectors and
    ``RewardSum`` expect; the four components are declared in the observation spec, as
    ``RewardSum`` declares its episode sum, and are 0 at a reset (no transition yet).

    The same class serves two places:

    - in a :class:`~torchrl.envs.TransformedEnv`, after the embedding and history transforms,
      for the values seen during collection (logging);
    - on a sampled batch (``transform(batch)``, or as a replay buffer transform), where it
      relabels ``("next", ...)`` with the current heads: the rewards are a pure function of the
      stored embeddings and success, so they can always be recomputed. A tensordict without a
      ``"next"`` entry is relabelled at its root.

    The transform refers to the :class:`TemporalReward` (``.reward``) without owning it: the
    reward stays on the device it was put on (the training device), whatever device the env
    moves its transforms to, and inputs are moved to it and rewards back to the batch's device.
    Its state is the env's all the same: ``env.state_dict()`` holds it under the transform's
    prefix and ``reward.`` (``transform.reward.*``, or ``transforms.<i>.reward.*`` in a
    ``Compose``: the heads, s_g, the baselines), and ``env.load_state_dict`` restores it into the
    referenced reward, so an env checkpointed alone keeps its heads.
    In a batched env put the transform on the outer env so the workers do not run stale copies
    of the heads.

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from temporal_torchrl.rewards import TemporalReward
        >>> D = 8
        >>> transform = TemporalRewardTransform(
        ...     TemporalReward(D, torch.randn(D), torch.randn(D), directional="d3"))
        >>> s = torch.randn(4, D)
        >>> batch = TensorDict({"next": {"embedding": s, "initial_embedding": s,
        ...     "previous_embedding": s, "success": torch.zeros(4, 1, dtype=torch.bool)}}, [4])
        >>> transform(batch)["next", "reward"].shape
        torch.Size([4, 1])
    """

    def __init__(self, reward: TemporalReward):
        if not isinstance(reward, TemporalReward):
            raise ValueError(f"reward={type(reward).__name__}; expected a TemporalReward.")
        input_keys = INPUT_KEYS + ((WINDOW_KEY,) if reward.window_length else ())
        super().__init__(in_keys=list(input_keys), out_keys=list(REWARD_KEYS))
        self.input_keys = input_keys
        # Referenced, not registered: an env's ``.to(device)`` must not move the heads the
        # trainer updates on the training device.
        self.__dict__["reward"] = reward

    # The reward is referenced, not registered (see __init__), so its state goes through these.
    def _save_to_state_dict(self, destination: dict, prefix: str, keep_vars: bool) -> None:
        super()._save_to_state_dict(destination, prefix, keep_vars)
        for key, value in self.reward.state_dict(keep_vars=keep_vars).items():
            destination[f"{prefix}{REWARD_PREFIX}{key}"] = value

    def _load_from_state_dict(self, state_dict: dict, prefix: str, local_metadata: dict,
                              strict: bool, missing_keys: list, unexpected_keys: list,
                              error_msgs: list) -> None:
        own = f"{prefix}{REWARD_PREFIX}"
        saved = {key.removeprefix(own): value for key, value in state_dict.items()
                 if key.startswith(own)}
        super()._load_from_state_dict(state_dict, prefix, local_metadata, strict, missing_keys,
                                      unexpected_keys, error_msgs)
        # torch counts the reward's keys as unexpected (not a registered child); they are ours.
        unexpected_keys[:] = [key for key in unexpected_keys if not key.startswith(own)]
        if not saved:
            missing_keys += [own + key for key in self.reward.state_dict()]
            return
        result = self.reward.load_state_dict(saved, strict=False)
        missing_keys += [own + key for key in result.missing_keys]
        unexpected_keys += [own + key for key in result.unexpected_keys]

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        inputs = [next_tensordict.get(key, None) for key in self.input_keys]
        missing = [key for key, value in zip(self.input_keys, inputs, strict=True)
                   if value is None]
        if missing:
            window = (f" (EmbeddingHistoryTransform(window_length={self.reward.window_length}), "
                      f"EpisodeReplayBuffer(window_length={self.reward.window_length}))"
                      if WINDOW_KEY in missing else "")
            raise KeyError(
                f"TemporalRewardTransform: missing {missing} (needs {list(self.input_keys)}). In "
                "an env put EmbeddingTransform and EmbeddingHistoryTransform before it; a stored "
                f"batch must keep those keys under 'next'{window}.")
        device = self.reward.goal_embedding.device
        with torch.no_grad():
            rewards = self.reward(*(value.to(device, non_blocking=True) for value in inputs))
        for key, value in rewards.items():
            next_tensordict.set(key, value.to(inputs[0].device, non_blocking=True))
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
               ) -> TensorDictBase:
        # Rewards belong to transitions: the components read 0 until the first step.
        for key in COMPONENT_KEYS:
            tensordict_reset.set(key, torch.zeros((*tensordict_reset.batch_size, 1),
                                                  device=tensordict_reset.device))
        return tensordict_reset

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        # Stored batches only (an env calls _call): the recipe's relabel phase
        # (temporal_torchrl.training.timing).
        with timeit("time/relabel"):
            next_tensordict = tensordict.get("next", None)
            self._call(tensordict if next_tensordict is None else next_tensordict)
        return tensordict

    def transform_reward_spec(self, reward_spec: Composite) -> Composite:
        reward = reward_spec["reward"]
        reward_spec["reward"] = Unbounded(shape=reward.shape, dtype=torch.float32,
                                          device=reward.device)
        return reward_spec

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        for key in COMPONENT_KEYS:
            observation_spec[key] = Unbounded(shape=(*observation_spec.shape, 1),
                                              dtype=torch.float32,
                                              device=observation_spec.device)
        return observation_spec

    def extra_repr(self) -> str:
        return f"reward={self.reward.extra_repr()}"
