"""A task's temporal reward: goal and baseline texts (thesis 4.2.2) embedded by an encoder."""

from __future__ import annotations

from typing import Any

from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs.tasks import GENERIC_BASELINE, get_task
from temporal_torchrl.rewards import TemporalReward


def baseline_text(task: str, baseline: str = "generic") -> str:
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


def make_temporal_reward(task: str, encoder: Encoder, *, positional: str | None = "furl",
                         directional: str | None = "d3", baseline: str = "generic",
                         **reward_options: Any) -> TemporalReward:
    """The temporal reward of ``task``, with goal and baseline texts embedded by ``encoder``.

    Args:
        task: the task whose goal prompt (:func:`~temporal_torchrl.envs.get_task`) is g.
        encoder: its text side embeds the goal prompt and the baseline.
        positional, directional: the reward names (None: that part is off).
        baseline: ``generic``, ``tailored`` (the task's own, thesis 4.2.2) or any text.
        **reward_options: :class:`~temporal_torchrl.rewards.TemporalReward`'s other arguments
            (``rho``, ``lambda_``, ``k``, ``alpha``, ``projection``, ``window_length``, ...).

    Example:
        >>> from temporal_torchrl.encoders import load_encoder
        >>> encoder = load_encoder("metaworld_small")
        >>> reward = make_temporal_reward("drawer-open", encoder, rho=1.0, lambda_=4.0)
        >>> reward.positional, reward.directional
        ('furl', 'd3')
    """
    texts = encoder.embed_text([get_task(task).goal_prompt, baseline_text(task, baseline)])
    return TemporalReward(encoder.dim, texts[0].float().cpu(), texts[1].float().cpu(),
                          positional=positional, directional=directional, **reward_options)
