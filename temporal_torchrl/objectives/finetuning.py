"""Reward-finetuning losses for the positional (FuRL) and directional reward heads.

All are TorchRL :class:`~torchrl.objectives.LossModule` s that read one batch from
``EpisodeReplayBuffer.finetuning.sample()`` (:class:`~temporal_torchrl.data.FinetuningSampler`
and :class:`~temporal_torchrl.data.FinetuningLayout`):

- ``"negative"``: states of failed episodes (``embedding`` s_t, ``initial_embedding`` s_0,
  ``previous_embedding`` s_{t-k}, and ``embedding_window`` s_{t-K+1} .. s_t for a reward that
  reads a window);
- ``"positive"`` (stage 2 only): valid positive states of successful episodes (step > gap);
- ``"positive_pair"`` (stage 2, when a positive run is longer than the gap): ``"later"`` s_i and
  ``"earlier"`` s_{i-gap} from one positive episode.

The stage is read from the batch: stage 2 (thesis 3.1.3.2, 4.3.3.2) starts as soon as the buffer
holds a positive episode, which is when the batch starts to carry ``"positive"``. Each loss owns
only its heads, so ``torch.optim.Adam(loss.parameters(), lr=1e-4)`` is its optimizer.
:func:`finetuning_losses` builds the losses a reward's registered objectives ask for:
:class:`PositionalRankingLoss` (thesis 3.1.3), :class:`DirectionalLoss` (thesis 4.3.3) and, beyond
the thesis (section 6.4 proposal), :class:`CertaintyLoss`.

The rewards are computed by the :class:`~temporal_torchrl.rewards.TemporalReward` itself
(:meth:`~temporal_torchrl.rewards.TemporalReward.positional_reward`,
:meth:`~temporal_torchrl.rewards.TemporalReward.directional_reward`), the same calls the env
transform and the replay relabelling make: a loss holds no copy of the variant, alpha, projection
or text embeddings, so it can never drift from the reward the agent is trained on.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from temporal_torchrl.modules import relu
from temporal_torchrl.rewards import (
    DIRECTIONAL,
    TemporalReward,
    direction_certainty,
    objective_of,
    reference_scales,
)

#: The release's optimizer settings for the heads (prior-implementations.md).
HEADS_LEARNING_RATE = 1e-4


def ranking_loss(preferred: Tensor, other: Tensor, delta: float) -> Tensor:
    """FuRL's ranking loss l_delta(s_p, s_n) = max(0, r(s_n) - r(s_p) + delta) (thesis 3.1.3)."""
    return relu(other - preferred + delta)


class PositionalRankingLoss(LossModule):
    """FuRL's ranking losses for the positional heads f^P (thesis 3.1.3, eq. 3.1-3.4).

    Stage 1 (negatives only), eq. 3.1 with the release's l2 margin: for every pair (i, j) of the
    batch with ``||s_i - s_g|| - ||s_j - s_g|| < -l2_margin`` (s_i clearly closer to the goal
    image embedding s_g), ``l_delta(s_i, s_j)``; summed over j, averaged over i.

    Stage 2: ``L = L_pos-neg + L_pos-pos`` (eq. 3.2-3.4), each the mean over the batch of
    ``l_delta(s^p, s^n)`` and ``l_delta(s^p_i, s^p_{i-gap})``. The stage-1 term is dropped.
    The rewards of all the batch's groups come from one :meth:`positional_reward` call on the
    groups concatenated: one batch through the heads.

    Args:
        reward: the :class:`TemporalReward` whose positional heads are trained (its variant,
            goal and baseline text embeddings, alpha and projection are used as they are).
        goal_image_embedding: s_g ``[D]``, see :func:`temporal_torchrl.data.goal_image_embedding`.
        delta: ranking margin (0.1).
        l2_margin: how much closer to s_g a negative must be to be preferred (0.2).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from temporal_torchrl.rewards import TemporalReward
        >>> D = 8
        >>> reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="furl")
        >>> loss = PositionalRankingLoss(reward, torch.randn(D))
        >>> states = TensorDict({"embedding": torch.randn(16, D),
        ...                      "initial_embedding": torch.randn(16, D),
        ...                      "previous_embedding": torch.randn(16, D)}, [16])
        >>> out = loss(TensorDict({"negative": states}, [16]))
        >>> out["loss_positional"].requires_grad, int(out["stage"])
        (True, 1)
    """

    #: The key of the loss to minimise in the output.
    loss_key = "loss_positional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *,
                 delta: float = 0.1, l2_margin: float = 0.2) -> None:
        super().__init__()
        if reward.positional_heads is None:
            raise ValueError(f"reward.positional={reward.positional!r} has no trainable heads; "
                             "a positional ranking loss needs furl or p1-p4.")
        self.heads = reward.positional_heads
        _reference(self, reward)
        self.delta = delta
        self.l2_margin = l2_margin
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())

    def positional_reward(self, states: TensorDictBase) -> Tensor:
        """r^VLM_P of a batch of states (with gradients into the heads)."""
        return self.reward.positional_reward(states["embedding"], states["initial_embedding"],
                                             states["previous_embedding"])

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch: ``loss_positional`` (to minimise), the parts, ``stage`` and
        ``summed_parts``."""
        zero = self.goal_image_embedding.new_zeros(())
        parts = {}
        stage = 2 if "positive" in tensordict.keys() else 1
        groups = {name: states for name, states in _state_groups(tensordict).items()
                  if stage == 2 or name == "negative"}
        rewards = _split_call(self.positional_reward, groups, _POSITIONAL_KEYS)
        if stage == 1 and "negative" in rewards:
            distance = (groups["negative"]["embedding"]
                        - self.goal_image_embedding).norm(dim=-1)
            closer = (distance.unsqueeze(1) - distance.unsqueeze(0)) < -self.l2_margin
            pairwise = ranking_loss(rewards["negative"].unsqueeze(1),
                                    rewards["negative"].unsqueeze(0), self.delta)
            parts["loss_neg_neg"] = (pairwise * closer).sum(1).mean()
        if stage == 2:
            if "negative" in rewards:
                parts["loss_pos_neg"] = ranking_loss(rewards["positive"], rewards["negative"],
                                                     self.delta).mean()
            if "later" in rewards:
                parts["loss_pos_pos"] = ranking_loss(rewards["later"], rewards["earlier"],
                                                     self.delta).mean()
        return _loss_output(self.loss_key, parts, zero, stage)


class DirectionalLoss(LossModule):
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
        same_position: ``True`` (default, the thesis text): the towards-goal and opposite terms
            use the variant's own position part at s_t, like the observed term. ``False``
            reproduces the thesis's release, where D4 and D5 score those two terms with the
            plain position n(s_t) (D3's input) while the observed term keeps D4's n(s_t - s_0)
            or D5's goal-baseline position. Other variants are the same either way.
    """

    #: The key of the loss to minimise in the output.
    loss_key = "loss_directional"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor, *,
                 same_position: bool = True) -> None:
        super().__init__()
        if reward.directional_heads is None:
            raise ValueError("reward.directional=None: a directional loss needs one of "
                             f"{', '.join(DIRECTIONAL)}.")
        self.heads = reward.directional_heads
        _reference(self, reward)
        self.same_position = same_position
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())

    def directional_reward(self, direction_end: Tensor, direction_start: Tensor,
                           states: TensorDictBase, position: Tensor | None = None,
                           variant: str | None = None, window: Tensor | None = None) -> Tensor:
        """r_D of the direction ``direction_end - direction_start`` at ``position`` (or of the
        path ``window``, for a reward that reads one)."""
        return self.reward.directional_reward(direction_end, direction_start,
                                              states["initial_embedding"], position=position,
                                              variant=variant, window=window)

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch: ``loss_directional`` (to minimise), the parts, ``stage`` and
        ``summed_parts``."""
        remember_certainty_references(self.reward, tensordict)
        # The release scores the contrasted direction at the plain position n(s_t): D3's input.
        variant = self.reward.directional
        contrast_variant = "d3" if not self.same_position and variant in ("d4", "d5") else variant
        length = self.reward.window_length
        stage = 2 if "positive" in tensordict.keys() else 1
        terms: dict[str, _DirectionTerm] = {}
        negative = tensordict.get("negative", None)
        if negative is not None:
            s_t = negative["embedding"]
            s_g = self.goal_image_embedding.expand_as(s_t)
            window = _window(negative, length)
            terms["negative_observed"] = _DirectionTerm.observed(negative, variant, window)
            terms["towards_goal"] = _DirectionTerm(
                contrast_variant, s_g, s_t, negative["initial_embedding"], s_t, None,
                straight_path=length is not None)
        if stage == 2:
            positive = tensordict["positive"]
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
        if stage == 2:
            parts["loss_positive"] = (rewards["opposite"].mean()
                                      - rewards["positive_observed"].mean())
        return _loss_output(self.loss_key, parts, self.goal_image_embedding.new_zeros(()), stage)

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

            def joined(field: str, chosen: list[_DirectionTerm] = chosen) -> Tensor | None:
                values = [getattr(term, field) for term in chosen]
                return None if values[0] is None else _joined(values)

            scores = self.reward.directional_reward(
                joined("end"), joined("start"), joined("initial"), position=joined("position"),
                variant=chosen[0].variant, window=joined("window"),
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


class CertaintyLoss(LossModule):
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

    Beta and c come from the reward (``reward.certainty_bandwidth``, ``certainty_prior``); the
    loss owns no state besides s_g, which the recipe saves.

    Args:
        reward: the :class:`TemporalReward` whose directional heads are trained; its reward must
            score one direction ``s - s_prev`` (not a window).
        goal_image_embedding: s_g ``[D]``.
    """

    #: The key of the loss to minimise in the output.
    loss_key = "loss_certainty"

    def __init__(self, reward: TemporalReward, goal_image_embedding: Tensor) -> None:
        super().__init__()
        if reward.directional_heads is None:
            raise ValueError("reward.directional=None: a certainty loss needs a directional "
                             f"reward with heads, e.g. d_certainty; one of "
                             f"{', '.join(DIRECTIONAL)}.")
        if reward.window_length is not None:
            raise ValueError(f"reward.directional={reward.directional!r} reads a window; the "
                             "certainty target is defined for one direction s_t - s_(t-k).")
        self.heads = reward.directional_heads
        _reference(self, reward)
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch: ``loss_certainty`` (to minimise), its parts, the mean targets
        of the observed directions, ``stage`` and ``summed_parts``."""
        remember_certainty_references(self.reward, tensordict)
        stage = 2 if "positive" in tensordict.keys() else 1
        groups = {name: tensordict[name] for name in ("negative", "positive")
                  if name in tensordict.keys()}
        zero = self.goal_image_embedding.new_zeros(())
        if not groups:
            return _loss_output(self.loss_key, {}, zero, stage)
        positions, directions, labels = _references(groups)
        scales = reference_scales(positions, directions)

        def certainty(position: Tensor, direction: Tensor, exclude: Tensor | None = None
                      ) -> Tensor:
            return direction_certainty(position, direction, positions, directions, labels,
                                       bandwidth=self.reward.certainty_bandwidth,
                                       prior=self.reward.certainty_prior, scales=scales,
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
        return _loss_output(self.loss_key, parts, zero, stage, out)


def finetuning_losses(reward: TemporalReward, goal_image_embedding: Tensor, *,
                      delta: float = 0.1, l2_margin: float = 0.2,
                      same_position: bool = True) -> list[LossModule]:
    """The losses that finetune ``reward``'s heads, by each part's registered objective
    (:func:`~temporal_torchrl.rewards.register_reward`): :class:`PositionalRankingLoss` for a
    positional part with heads, :class:`DirectionalLoss` or :class:`CertaintyLoss` for a
    directional part with heads. Give each its own optimizer over ``loss.parameters()``.

    Args:
        reward: the reward whose heads are trained.
        goal_image_embedding: s_g ``[D]``.
        delta, l2_margin: of :class:`PositionalRankingLoss`.
        same_position: of :class:`DirectionalLoss`.
    """
    losses: list[LossModule] = []
    if reward.positional_heads is not None:
        losses.append(PositionalRankingLoss(reward, goal_image_embedding, delta=delta,
                                            l2_margin=l2_margin))
    if reward.directional_heads is not None:
        if objective_of(reward.directional) == "certainty":
            losses.append(CertaintyLoss(reward, goal_image_embedding))
        else:
            losses.append(DirectionalLoss(reward, goal_image_embedding,
                                          same_position=same_position))
    return losses


def remember_certainty_references(reward: TemporalReward, tensordict: TensorDictBase) -> None:
    """Refresh ``reward.certainty`` (``certainty_scaling``) with the batch's labelled states; a
    no-op without it or without labelled states."""
    groups = {name: tensordict[name] for name in ("negative", "positive")
              if name in tensordict.keys()}
    if reward.certainty is not None and groups:
        reward.certainty.remember(*_references(groups))


def _references(groups: dict[str, TensorDictBase]) -> tuple[Tensor, Tensor, Tensor]:
    """Positions s_t, observed directions s_t - s_(t-k) and labels (+1 positive, -1 negative)
    of the batch's states, in the order of ``groups``."""
    positions = torch.cat([states["embedding"] for states in groups.values()])
    directions = torch.cat([states["embedding"] - states["previous_embedding"]
                            for states in groups.values()])
    labels = torch.cat([torch.full((states.shape[0],), 1.0 if name == "positive" else -1.0)
                        for name, states in groups.items()])
    return positions, directions, labels.to(positions.device)


#: The state keys a positional reward reads.
_POSITIONAL_KEYS = ("embedding", "initial_embedding", "previous_embedding")


def _state_groups(tensordict: TensorDictBase) -> dict[str, TensorDictBase]:
    """The batch's groups of states by name: ``negative``, ``positive`` and the pair's
    ``later`` and ``earlier``, those present."""
    groups = {name: tensordict[name] for name in ("negative", "positive")
              if name in tensordict.keys()}
    pair = tensordict.get("positive_pair", None)
    if pair is not None:
        groups.update(later=pair["later"], earlier=pair["earlier"])
    return groups


def _loss_output(loss_key: str, parts: dict[str, Tensor], zero: Tensor, stage: int,
                 extra: dict[str, Tensor] | None = None) -> TensorDict:
    """A finetuning loss's output: ``loss_key`` the sum of ``parts`` (to minimise), each part
    detached, ``stage``, ``summed_parts`` (how many: 0 when the batch held nothing to score,
    and ``loss_key`` is a constant), and ``extra`` (metrics) as given."""
    out = {**(extra or {}), **{name: value.detach() for name, value in parts.items()}}
    # Not sum(parts, zero): compiled by inductor, one part plus a zero lost its gradient
    # (simplified to the part, the output merged with the part's detached copy), and the
    # trainer, which then skipped losses without a gradient, trained no heads in stage 1
    # (torch 2.14); it now raises on a loss that summed parts without one.
    out[loss_key] = torch.stack(list(parts.values())).sum() if parts else zero
    out["stage"] = torch.tensor(stage)
    out["summed_parts"] = torch.tensor(len(parts))
    return TensorDict(out, [])


def _split_call(function: Callable[[TensorDictBase], Tensor],
                groups: dict[str, TensorDictBase], keys: tuple[str, ...]) -> dict[str, Tensor]:
    """``function`` of every group, called once on the groups' ``keys`` concatenated: one batch
    through the heads instead of one per group (the heads treat each state on its own)."""
    if not groups:
        return {}
    if len(groups) == 1:  # stage 1: the negatives alone, nothing to join
        (name, states), = groups.items()
        return {name: function(states)}
    sizes = [states.shape[0] for states in groups.values()]
    joined = TensorDict({key: _joined([states[key] for states in groups.values()])
                         for key in keys}, [sum(sizes)])
    values = function(joined).split(sizes)
    return dict(zip(groups, values, strict=True))


def _joined(tensors: list[Tensor]) -> Tensor:
    """``torch.cat(tensors)``, as a view when the tensors lie one after the other in one storage,
    as the finetuning batch's groups do (:class:`~temporal_torchrl.data.FinetuningLayout`
    converts all their embeddings in one tensor): joining the groups then copies nothing."""
    first = tensors[0]
    if len(tensors) == 1:
        return first
    # Compiled, inductor plans the copy itself; the storage checks would break the graph.
    if (torch.compiler.is_compiling() or first.dim() == 0
            or any(tensor.requires_grad for tensor in tensors)):
        return torch.cat(tensors)
    storage, offset = first.untyped_storage().data_ptr(), first.storage_offset()
    for tensor in tensors:
        if not (tensor.dtype == first.dtype and tensor.device == first.device
                and tensor.shape[1:] == first.shape[1:] and tensor.stride() == first.stride()
                and tensor.untyped_storage().data_ptr() == storage
                and tensor.storage_offset() == offset):
            return torch.cat(tensors)
        offset += tensor.shape[0] * first.stride(0)
    rows = sum(tensor.shape[0] for tensor in tensors)
    return first.as_strided((rows, *first.shape[1:]), first.stride(), first.storage_offset())


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


def _reference(loss: LossModule, reward: TemporalReward) -> None:
    # Referenced, not registered as a submodule: the loss's parameters and state_dict stay its
    # own heads (one optimizer per loss), while the reward's variant, text embeddings, alpha and
    # projection are read at every call.
    loss.__dict__["reward"] = reward
