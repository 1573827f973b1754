"""Fixed-goal Metaworld tasks as TorchRL envs, the task registry, scripted experts, and the
canonical temporal env composition."""

from temporal_torchrl.envs.experts import (
    collect_expert_episodes,
    collect_successful_experts,
    first_success_index,
)
from temporal_torchrl.envs.metaworld_env import MetaworldEnv, make_env
from temporal_torchrl.envs.task_reward import baseline_text, make_temporal_reward
from temporal_torchrl.envs.tasks import (
    EVALUATION_TASKS,
    GENERIC_BASELINE,
    TASKS,
    TaskSpec,
    get_task,
)
from temporal_torchrl.envs.temporal import make_temporal_env

__all__ = [
    "EVALUATION_TASKS",
    "GENERIC_BASELINE",
    "TASKS",
    "MetaworldEnv",
    "TaskSpec",
    "baseline_text",
    "collect_successful_experts",
    "collect_expert_episodes",
    "first_success_index",
    "get_task",
    "make_env",
    "make_temporal_env",
    "make_temporal_reward",
]
