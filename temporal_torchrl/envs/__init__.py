"""Fixed-goal Metaworld tasks as TorchRL envs, the task registry and scripted experts."""

from temporal_torchrl.envs.experts import collect_expert_episodes, first_success_index
from temporal_torchrl.envs.metaworld_env import MetaworldEnv, make_env
from temporal_torchrl.envs.tasks import (
    EVALUATION_TASKS,
    GENERIC_BASELINE,
    TASKS,
    TaskSpec,
    get_task,
)

__all__ = [
    "EVALUATION_TASKS",
    "GENERIC_BASELINE",
    "TASKS",
    "MetaworldEnv",
    "TaskSpec",
    "collect_expert_episodes",
    "first_success_index",
    "get_task",
    "make_env",
]
