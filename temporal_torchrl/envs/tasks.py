"""Registry of the Metaworld MT50 tasks: names, language prompts, baselines, budgets and experts.

Tasks are keyed by their short Metaworld name without the ``-v3`` suffix (``"drawer-open"``).
The six evaluation tasks of the thesis (chapter 5, Table 5.1) carry the goal prompt l_g and the
tailored baseline l_b used by the prior implementations, and the episode budget e of the
stage-2 metric RAS(e; w). Every other MT50 task has a goal prompt written for this project, no
tailored baseline (use :data:`GENERIC_BASELINE`) and no RAS budget.

Example:
    >>> from temporal_torchrl.envs import TASKS, get_task
    >>> get_task("push").goal_prompt
    'push the puck to a goal'
    >>> len(TASKS)
    50
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

GENERIC_BASELINE: str = "robot arm beside table"
"""The task-independent baseline text l_b (thesis section 4.2)."""

EVALUATION_TASKS: tuple[str, ...] = (
    "drawer-open",
    "door-open",
    "window-open",
    "window-close",
    "push",
    "button-press-topdown",
)
"""The six evaluation tasks, in the thesis's order (chapter 5)."""


@dataclass(frozen=True)
class TaskSpec:
    """One Metaworld task and the texts and budget the reward shaping needs.

    Attributes:
        name: short name, e.g. ``"drawer-open"``.
        env_id: Metaworld's id, e.g. ``"drawer-open-v3"``.
        goal_prompt: the goal text l_g embedded by the VLM's text encoder.
        tailored_baseline: task-specific baseline text l_b, or ``None`` (use the generic one).
        ras_budget: the episode budget e of RAS(e; w) (thesis Table 5.1), or ``None``.
    """

    name: str
    env_id: str
    goal_prompt: str
    tailored_baseline: str | None = None
    ras_budget: int | None = None

    @property
    def is_evaluation_task(self) -> bool:
        """Whether the thesis evaluates on this task (it then has a baseline and a budget)."""
        return self.name in EVALUATION_TASKS

    @property
    def baseline(self) -> str:
        """The tailored baseline when the task has one, otherwise :data:`GENERIC_BASELINE`."""
        return self.tailored_baseline or GENERIC_BASELINE

    def make_expert(self) -> Any:
        """A fresh instance of Metaworld's scripted policy for this task (``get_action(obs)``).

        The policies read the goal from ``obs[36:39]``; on goal-hidden envs the caller must
        write the true goal there (see :func:`temporal_torchrl.envs.collect_expert_episodes`).
        """
        # Imported here so that reading the registry does not load MuJoCo.
        from metaworld.policies import ENV_POLICY_MAP

        return ENV_POLICY_MAP[self.env_id]()


_EVALUATION_SPECS = (
    TaskSpec("drawer-open", "drawer-open-v3", "open a drawer", "closed drawer", 300),
    TaskSpec("door-open", "door-open-v3", "open a door with a revolving joint",
             "closed door with a revolving joint", 400),
    TaskSpec("window-open", "window-open-v3", "push and open a window", "closed window", 200),
    TaskSpec("window-close", "window-close-v3", "push and close a window", "open window", 200),
    TaskSpec("push", "push-v3", "push the puck to a goal", "puck on table not at goal", 1000),
    TaskSpec("button-press-topdown", "button-press-topdown-v3", "press a button from the top",
             "unpressed button", 400),
)

# Goal prompts for the other 44 MT50 tasks, written in the style of the evaluation prompts.
_OTHER_PROMPTS = {
    "assembly": "put the ring onto the peg",
    "basketball": "dunk the basketball into the basket",
    "bin-picking": "pick the puck from one bin and place it into the other bin",
    "box-close": "grasp the lid and close the box",
    "button-press-topdown-wall": "press a button from the top behind a wall",
    "button-press": "press a button from the front",
    "button-press-wall": "press a button from the front behind a wall",
    "coffee-button": "press the button on the coffee machine",
    "coffee-pull": "pull the coffee mug away from the coffee machine",
    "coffee-push": "push the coffee mug under the coffee machine",
    "dial-turn": "rotate a dial by 180 degrees",
    "disassemble": "pick the ring off the peg",
    "door-close": "close a door with a revolving joint",
    "door-lock": "lock the door by rotating the lock clockwise",
    "door-unlock": "unlock the door by rotating the lock counter-clockwise",
    "hand-insert": "insert the gripper into a hole",
    "drawer-close": "push and close a drawer",
    "faucet-open": "rotate the faucet counter-clockwise",
    "faucet-close": "rotate the faucet clockwise",
    "hammer": "hammer a screw into the wall",
    "handle-press-side": "press a handle down sideways",
    "handle-press": "press a handle down",
    "handle-pull-side": "pull a handle up sideways",
    "handle-pull": "pull a handle up",
    "lever-pull": "pull a lever down by 90 degrees",
    "pick-place-wall": "pick a puck and place it at a goal behind a wall",
    "pick-out-of-hole": "pick a puck out of a hole",
    "pick-place": "pick a puck and place it at a goal",
    "plate-slide": "slide a plate into a cabinet",
    "plate-slide-side": "slide a plate into a cabinet sideways",
    "plate-slide-back": "slide a plate out of a cabinet",
    "plate-slide-back-side": "slide a plate out of a cabinet sideways",
    "peg-insert-side": "insert a peg sideways into a hole",
    "peg-unplug-side": "unplug a peg sideways",
    "soccer": "kick a soccer ball into the goal",
    "stick-push": "grasp a stick and push a box with the stick",
    "stick-pull": "grasp a stick and pull a box with the stick",
    "push-wall": "push the puck to a goal behind a wall",
    "push-back": "push the puck back to a goal",
    "reach": "reach a goal position",
    "reach-wall": "reach a goal position behind a wall",
    "shelf-place": "pick a puck and place it onto a shelf",
    "sweep-into": "sweep a puck into a hole",
    "sweep": "sweep a puck off the table",
}

TASKS: dict[str, TaskSpec] = {spec.name: spec for spec in _EVALUATION_SPECS}
TASKS.update(
    {name: TaskSpec(name, f"{name}-v3", prompt) for name, prompt in _OTHER_PROMPTS.items()})


def get_task(name: str | TaskSpec) -> TaskSpec:
    """The :class:`TaskSpec` named ``name`` (short name; a trailing ``-v3`` is accepted).

    Raises:
        ValueError: for an unknown name; the message lists the valid names.
    """
    if isinstance(name, TaskSpec):
        return name
    key = name.removesuffix("-v3") if isinstance(name, str) else name
    if key not in TASKS:
        raise ValueError(
            f"Unknown task {name!r}: expected one of the 50 Metaworld MT50 short names "
            f"{sorted(TASKS)} (e.g. 'drawer-open'); the evaluation tasks are "
            f"{list(EVALUATION_TASKS)}."
        )
    return TASKS[key]
