"""Evaluation episodes of the deterministic policy, apart from training (``eval.*``).

The thesis measures a run by its training episodes (TTFS, TT50S, RAS), exploration included.
An evaluation instead runs the policy's mean action, with no relay and no exploration noise, on
layouts of its own, as Metaworld's benchmark, FuRL's code and TorchRL's SAC recipe do (and as
the thesis's section 6 proposes): one set of parameters, measured over several episodes.
"""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from temporal_torchrl import defaults
from temporal_torchrl.envs.metaworld_env import MetaworldEnv
from temporal_torchrl.params import EnvParams, env_params


class PolicyEvaluation:
    """``episodes`` episodes of a policy's deterministic action on the evaluation layouts.

    Random goals: held-out layouts, the seed's ``"evaluation"`` stream
    (:func:`~temporal_torchrl.envs.metaworld_env.layout_generator`), which training and the
    scripted experts never draw from; the same ``episodes`` layouts at every evaluation, so that
    evaluations differ only by the policy. Fixed goals: the run's own layout. The env is the
    task's state env, without rendering or VLM reward: the policy reads the state alone, and an
    evaluation touches nothing training uses (no replay, no counters, no random generator of
    torch's).

    Args:
        env: the run's :class:`~temporal_torchrl.params.EnvParams` (its task, seed, goal
            setting and episode length; the frames are not rendered), or a task name.
        episodes: episodes per evaluation (:class:`~temporal_torchrl.params.EvalParams`).
        device: where the policy runs (the env's outputs are put there).

    Example:
        >>> from tensordict.nn import TensorDictModule
        >>> import torch
        >>> still = TensorDictModule(lambda obs: torch.zeros(*obs.shape[:-1], 4),
        ...                          in_keys=["observation"], out_keys=["action"])
        >>> from temporal_torchrl.params import EnvParams
        >>> env = EnvParams("window-close", goal="random", max_episode_steps=20)
        >>> evaluation = PolicyEvaluation(env, episodes=2)
        >>> result = evaluation(still)
        >>> result["episodes"], result["success_rate"], result["episode_length"]
        (2, 0.0, 20.0)
    """

    def __init__(self, env: str | EnvParams, episodes: int = defaults.EVAL_EPISODES, *,
                 device: str | torch.device = "cpu") -> None:
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
            raise ValueError(f"episodes={episodes!r}; expected a positive integer, the "
                             "evaluation episodes per evaluation (e.g. 10).")
        params = env_params(env)
        self.episodes = episodes
        self.env = MetaworldEnv(params.task, params.seed, goal=params.goal, stream="evaluation",
                                max_episode_steps=params.max_episode_steps, device=device)

    def __call__(self, policy: TensorDictModuleBase) -> dict[str, float]:
        """Run the evaluation: ``episodes``, ``success_rate`` (success at any step, as the
        training episodes count it), ``final_success_rate`` (at the last step, as FuRL's
        evaluation does), mean ``return`` (sparse task reward) and mean ``episode_length``."""
        self.env.restart_layouts()
        success = final_success = total_return = length = 0.0
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            for _ in range(self.episodes):
                episode = self.env.rollout(self.env.max_episode_steps, policy,
                                           break_when_any_done=True)
                successes = episode["next", "success"].reshape(-1)
                success += float(successes.any())
                final_success += float(successes[-1])
                total_return += float(episode["next", "reward"].sum())
                length += len(successes)
        count = self.episodes
        return {"episodes": count, "success_rate": success / count,
                "final_success_rate": final_success / count, "return": total_return / count,
                "episode_length": length / count}

    def close(self) -> None:
        self.env.close()
