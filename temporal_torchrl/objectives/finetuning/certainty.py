"""The certainty loss of the directional heads (beyond the thesis, section 6.4 proposal), and the
certainty references the directional losses refresh."""

from __future__ import annotations

from collections.abc import Mapping

import torch
from tensordict import TensorDictBase
from torch import Tensor

from temporal_torchrl.objectives.finetuning.base import FinetuningLoss
from temporal_torchrl.rewards import (
    DIRECTIONAL,
    TemporalReward,
    direction_certainty,
    reference_scales,
)
from temporal_torchrl.rewards.registry import CERTAINTY_OPTIONS

#: The groups of the batch that carry a label: -1 for negatives, +1 for positives.
LABELLED_GROUPS = ("negative", "positive")


class CertaintyLoss(FinetuningLoss):
    """Squared error of the directional reward to the certainty target (beyond the thesis,
    section 6.4 proposal), for rewards registered with ``objective="certainty"`` (d_certainty).

    The thesis's directional loss only pushes directions up or down, so finetuned D3 saturates
    like an indicator; the proposal trains towards a target t instead. Here t is the kernel
    certainty of :func:`~temporal_torchrl.rewards.direction_certainty`, computed from the batch
    itself: the references are the batch's labelled states (position s_t, observed direction
    Δs_t = s_t - s_{t-k}, +1 for positives, -1 for negatives), and the queries are the four
    directions of the thesis's directional loss at s_t:

        L_neg = mean (r_D(s_t, Δs_t) - t(s_t, Δs_t))^2 + mean (r_D(s_t, Δ̂s_t) - t(s_t, Δ̂s_t))^2
        L_pos = mean (r_D(s_t, Δs_t) - t(s_t, Δs_t))^2 + mean (r_D(s_t, Δ̄s_t) - t(s_t, Δ̄s_t))^2

    on negative (stage 1 and 2) and positive (stage 2) states, with Δ̂s_t = s_g - s_t towards the
    goal image embedding and Δ̄s_t = s_{t-k} - s_t the opposite direction; ``loss_certainty`` is
    their sum. The certainty replaces the directional loss's fixed preference (observed negative
    and opposite down, towards-goal and observed positive up): a direction is pushed to +1 or -1
    only as far as the positives and negatives near it agree, and to 0 where none are near
    (towards-goal and opposite directions mostly are). The observed directions are their own
    references, so each leaves itself out (a state is not its own evidence).

    Beta and c are the reward's options ``certainty_bandwidth`` and ``certainty_prior``
    (``reward.options``; every reward registered with ``objective="certainty"`` has them,
    :data:`~temporal_torchrl.rewards.registry.CERTAINTY_OPTIONS`); the loss owns no state
    besides s_g, which the recipe saves.

    Args:
        reward: the :class:`TemporalReward` whose directional heads are trained; its reward must
            score one direction ``s - s_prev`` (not a window).
        goal_image_embedding: s_g ``[D]``.
        stage: 1 or 2 (see :class:`~temporal_torchrl.objectives.finetuning.base.FinetuningLoss`).
    """

    loss_key = "loss_certainty"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *,
                 stage: int) -> None:
        if reward.directional_heads is None:
            raise ValueError("reward.directional=None: a certainty loss needs a directional "
                             f"reward with heads, e.g. d_certainty; one of "
                             f"{', '.join(DIRECTIONAL)}.")
        if reward.window_length is not None:
            raise ValueError(f"reward.directional={reward.directional!r} reads a window; the "
                             "certainty target is defined for one direction s_t - s_(t-k).")
        if not set(CERTAINTY_OPTIONS) <= set(reward.options):
            raise ValueError(f"reward.directional={reward.directional!r} has no "
                             f"{' or '.join(CERTAINTY_OPTIONS)} option: the certainty loss "
                             "trains a reward registered with objective='certainty', such as "
                             "d_certainty.")
        super().__init__(reward, reward.directional_heads, goal_image_embedding, stage=stage)

    def terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The terms for one batch, ``loss_certainty_<group>`` of each labelled group
        (``loss_certainty`` is their sum), and the metrics ``target_<group>``, the mean target
        of the group's observed directions."""
        groups = _labelled(self.groups(tensordict))
        remember_certainty_references(self.reward, groups)
        if not groups:
            return {}
        positions, directions, labels = _references(groups)
        scales = reference_scales(positions, directions)

        def certainty(position: Tensor, direction: Tensor, exclude: Tensor | None = None
                      ) -> Tensor:
            return direction_certainty(position, direction, positions, directions, labels,
                                       bandwidth=self.reward.options["certainty_bandwidth"],
                                       prior=self.reward.options["certainty_prior"],
                                       scales=scales,
                                       exclude=exclude)

        leave_one_out = torch.eye(labels.numel(), dtype=torch.bool, device=labels.device)
        observed_targets = certainty(positions, directions, leave_one_out).split(
            [states.shape[0] for states in groups.values()])
        out, parts = {}, {}
        for (name, states), observed_target in zip(groups.items(), observed_targets,
                                                   strict=True):
            s_t, s_tk, s_0 = (states["embedding"], states["previous_embedding"],
                              states["initial_embedding"])
            # The contrasted direction of the thesis's loss: towards s_g, or back to s_(t-k).
            end = self.goal_image_embedding.expand_as(s_t) if name == "negative" else s_tk
            observed = self.reward.directional_reward(s_t, s_tk, s_0)
            contrasted = self.reward.directional_reward(end, s_t, s_0, position=s_t)
            parts[f"loss_certainty_{name}"] = (
                (observed - observed_target).pow(2).mean()
                + (contrasted - certainty(s_t, end - s_t)).pow(2).mean())
            out[f"target_{name}"] = observed_target.mean()
        return {**parts, **out}


def remember_certainty_references(reward: TemporalReward,
                                  groups: Mapping[str, TensorDictBase]) -> None:
    """Refresh ``reward.certainty`` (``certainty_scaling``) with the labelled states of a
    loss's ``groups`` (:meth:`~temporal_torchrl.objectives.finetuning.base.FinetuningLoss.groups`);
    a no-op without it or without labelled states."""
    labelled = _labelled(groups)
    if reward.certainty is not None and labelled:
        reward.certainty.remember(*_references(labelled))


def _labelled(groups: Mapping[str, TensorDictBase]) -> dict[str, TensorDictBase]:
    """The groups of :data:`LABELLED_GROUPS` among ``groups``, in that order."""
    return {name: groups[name] for name in LABELLED_GROUPS if name in groups}


def _references(groups: dict[str, TensorDictBase]) -> tuple[Tensor, Tensor, Tensor]:
    """Positions s_t, observed directions s_t - s_(t-k) and labels (+1 positive, -1 negative)
    of the batch's states, in the order of ``groups``."""
    positions = torch.cat([states["embedding"] for states in groups.values()])
    directions = torch.cat([states["embedding"] - states["previous_embedding"]
                            for states in groups.values()])
    labels = torch.cat([torch.full((states.shape[0],), 1.0 if name == "positive" else -1.0)
                        for name, states in groups.items()])
    return positions, directions, labels.to(positions.device)
