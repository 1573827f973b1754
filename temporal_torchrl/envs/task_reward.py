"""A task's temporal reward: goal and baseline texts (thesis 4.2.2) embedded by an encoder."""

from __future__ import annotations

from typing import Any

from torch import Tensor

from temporal_torchrl.defaults import BASELINE
from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs.tasks import GENERIC_BASELINE, get_task
from temporal_torchrl.rewards import TemporalReward


def baseline_text(task: str, baseline: str = BASELINE) -> str:
    """``generic`` -> the generic baseline, ``tailored`` -> the task's own, any other text as is.

    >>> baseline_text("drawer-open") == GENERIC_BASELINE
    True
    """
    if not isinstance(baseline, str) or not baseline.strip():
        raise ValueError(f"baseline={baseline!r}; expected 'generic', 'tailored' or a text.")
    if baseline == "generic":
        return GENERIC_BASELINE
    if baseline == "tailored":
        tailored = get_task(task).tailored_baseline
        if tailored is None:
            raise ValueError(f"baseline='tailored': {task} has no tailored baseline (only the "
                             "thesis's six evaluation tasks have one); use 'generic' or a text.")
        return tailored
    return baseline


def task_text_embeddings(task: str, encoder: Encoder,
                         baseline: str = BASELINE) -> tuple[Tensor, Tensor]:
    """g and b of ``task``: its goal prompt (:func:`~temporal_torchrl.envs.get_task`) and its
    baseline (:func:`baseline_text`), embedded by ``encoder``'s text side, float32 ``[D]`` each
    on the CPU."""
    texts = encoder.embed_text([get_task(task).goal_prompt, baseline_text(task, baseline)])
    return texts[0].float().cpu(), texts[1].float().cpu()


def make_temporal_reward(task: str, encoder: Encoder, *, baseline: str = BASELINE,
                         **reward_arguments: Any) -> TemporalReward:
    """The temporal reward of ``task``, with goal and baseline texts embedded by ``encoder``.

    Args:
        task: the task whose goal prompt (:func:`~temporal_torchrl.envs.get_task`) is g.
        encoder: its text side embeds the goal prompt and the baseline.
        baseline: ``generic``, ``tailored`` (the task's own, thesis 4.2.2) or any text.
        **reward_arguments: :class:`~temporal_torchrl.rewards.TemporalReward`'s arguments
            (``positional``, ``directional``, ``rho``, ``lambda_``, ``k``, ...), each defaulting
            to the training recipe's (:mod:`~temporal_torchrl.defaults`).

    Example:
        >>> from temporal_torchrl.encoders import load_encoder
        >>> encoder = load_encoder("metaworld_small")
        >>> reward = make_temporal_reward("drawer-open", encoder)
        >>> reward.positional, reward.directional, reward.rho, reward.lambda_
        ('furl', 'd3', 1.0, 4.0)
    """
    goal, baseline_embedding = task_text_embeddings(task, encoder, baseline)
    return TemporalReward(encoder.dim, goal, baseline_embedding, **reward_arguments)
