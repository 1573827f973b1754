"""The thesis's finetuning loss of the directional heads f^D (thesis 4.3.3)."""

from __future__ import annotations

from dataclasses import dataclass

from tensordict import TensorDictBase
from torch import Tensor

from temporal_torchrl.defaults import SAME_POSITION
from temporal_torchrl.objectives.finetuning.base import FinetuningLoss, joined
from temporal_torchrl.objectives.finetuning.certainty import remember_certainty_references
from temporal_torchrl.rewards import DIRECTIONAL, TemporalReward


class DirectionalLoss(FinetuningLoss):
    """Finetuning loss of the directional heads f^D (thesis 4.3.3); no margin.

    Stage 1, on negative states: ``L^D_neg = r_D(s_t, Δs_t) - r_D(s_t, Δ̂s_t)`` with the observed
    direction Δs_t = s_t - s_{t-k} and the direction towards the goal image embedding
    Δ̂s_t = s_g - s_t, both at the position s_t (batch means of each term).
    Stage 2 adds, on positive states, ``L^D_pos = r_D(s_t, Δ̄s_t) - r_D(s_t, Δs_t)`` with the
    opposite direction Δ̄s_t = s_{t-k} - s_t. The buffer never labels an episode's reset frame s_0
    (as in the reference implementations), so every observed direction is that of a real step.

    A reward that reads a window (d_sequence; beyond the thesis, section 6.3 proposal) gets the
    same terms with paths in place of directions, all at the position s_t: the observed window
    W_t = (s_{t-K+1} .. s_t); towards the goal the straight window from s_t to s_g
    (:func:`~temporal_torchrl.rewards.straight_window`: every step along s_g - s_t, scored with
    ``straight_path=True``, so the reward need not build it); opposite, W_t reversed
    (s_t .. s_{t-K+1}: every step negated, in reverse order). With K = 2 these are D3's three
    directions with k = 1.

    The terms are scored in two reward calls (the observed directions of both groups, then the
    contrasted ones), each one batch through the heads; a window reward's terms one by one.

    With ``reward.certainty_scaling`` the loss also refreshes the reward's certainty references
    (:class:`~temporal_torchrl.rewards.CertaintyMemory`) from the batch.

    Args:
        reward: the :class:`TemporalReward` whose directional heads are trained.
        goal_image_embedding: s_g ``[D]``.
        stage: 1 or 2 (see :class:`~temporal_torchrl.objectives.finetuning.base.FinetuningLoss`).
        same_position: ``True`` (the default,
            :data:`~temporal_torchrl.defaults.SAME_POSITION`; the thesis text): the
            towards-goal and opposite terms use the variant's own position part at s_t, like the
            observed term. ``False`` reproduces the thesis's release, where D4 and D5 score those
            two terms with the plain position n(s_t) (D3's input) while the observed term keeps
            D4's n(s_t - s_0) or D5's goal-baseline position. Other variants are the same either
            way.
    """

    loss_key = "loss_directional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *, stage: int,
                 same_position: bool = SAME_POSITION) -> None:
        if reward.directional_heads is None:
            raise ValueError("reward.directional=None: a directional loss needs one of "
                             f"{', '.join(DIRECTIONAL)}.")
        super().__init__(reward, reward.directional_heads, goal_image_embedding, stage=stage)
        self.same_position = same_position

    def terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The terms for one batch (``loss_directional`` is their sum): ``loss_negative``
        (L^D_neg), and in stage 2 ``loss_positive`` (L^D_pos)."""
        groups = self.groups(tensordict)
        remember_certainty_references(self.reward, groups)
        # The release scores the contrasted direction at the plain position n(s_t): D3's input.
        variant = self.reward.directional
        contrast_variant = "d3" if not self.same_position and variant in ("d4", "d5") else variant
        length = self.reward.window_length
        terms: dict[str, _DirectionTerm] = {}
        negative, positive = groups.get("negative"), groups.get("positive")
        if negative is not None:
            s_t = negative["embedding"]
            s_g = self.goal_image_embedding.expand_as(s_t)
            window = _window(negative, length)
            terms["negative_observed"] = _DirectionTerm.observed(negative, variant, window)
            terms["towards_goal"] = _DirectionTerm(
                contrast_variant, s_g, s_t, negative["initial_embedding"], s_t, None,
                straight_path=length is not None)
        if positive is not None:
            s_t, s_tk = positive["embedding"], positive["previous_embedding"]
            window = _window(positive, length)
            terms["positive_observed"] = _DirectionTerm.observed(positive, variant, window)
            terms["opposite"] = _DirectionTerm(
                contrast_variant, s_tk, s_t, positive["initial_embedding"], s_t,
                None if window is None else window.flip(-2))
        rewards = self._score(terms)
        parts = {}
        if negative is not None:
            parts["loss_negative"] = (rewards["negative_observed"].mean()
                                      - rewards["towards_goal"].mean())
        if positive is not None:
            parts["loss_positive"] = (rewards["opposite"].mean()
                                      - rewards["positive_observed"].mean())
        return parts

    def _score(self, terms: dict[str, _DirectionTerm]) -> dict[str, Tensor]:
        """r_D of every term, with one reward call per variant for the observed terms (the
        variant's own default position) and one for the contrasted ones (at s_t): the heads see
        the groups' states as one batch. Window terms are scored one by one: joining their
        windows ([B, K, D] each) would copy more than it saves."""
        if self.reward.window_length is not None:
            calls = [[name] for name in terms]
        else:
            kinds = {name: (term.variant, term.position is None) for name, term in terms.items()}
            calls = [[name for name in terms if kinds[name] == kind]
                     for kind in dict.fromkeys(kinds.values())]
        rewards: dict[str, Tensor] = {}
        for names in calls:
            chosen = [terms[name] for name in names]

            def join(field: str, chosen: list[_DirectionTerm] = chosen) -> Tensor | None:
                values = [getattr(term, field) for term in chosen]
                return None if values[0] is None else joined(values)

            scores = self.reward.directional_reward(
                join("end"), join("start"), join("initial"), position=join("position"),
                variant=chosen[0].variant, window=join("window"),
                straight_path=chosen[0].straight_path)
            rewards.update(zip(names, scores.split([term.end.shape[0] for term in chosen]),
                               strict=True))
        return rewards


@dataclass(frozen=True)
class _DirectionTerm:
    """One term of the directional loss: r_D of the direction ``end - start`` (or the path
    ``window``, or the straight path from ``start`` to ``end`` with ``straight_path``) at
    ``position`` (None: the variant's default), scored by ``variant``."""

    variant: str
    end: Tensor
    start: Tensor
    initial: Tensor
    position: Tensor | None
    window: Tensor | None
    straight_path: bool = False

    @classmethod
    def observed(cls, states: TensorDictBase, variant: str,
                 window: Tensor | None) -> _DirectionTerm:
        """The observed direction s_t - s_{t-k} (or window W_t) at the variant's default
        position."""
        return cls(variant, states["embedding"], states["previous_embedding"],
                   states["initial_embedding"], None, window)


def _window(states: TensorDictBase, length: int | None) -> Tensor | None:
    """The states' ``embedding_window`` when the reward reads one (``length`` not None)."""
    if length is None:
        return None
    window = states.get("embedding_window", None)
    if window is None:
        raise KeyError(f"the reward reads a window of {length} embeddings but the batch has no "
                       "'embedding_window'; build the replay buffer with "
                       f"EpisodeReplayBuffer(..., window_length={length}).")
    return window
