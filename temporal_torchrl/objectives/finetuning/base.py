"""What the finetuning losses share: :class:`FinetuningLoss`, the batch's groups and their join."""

from __future__ import annotations

import inspect
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from temporal_torchrl.defaults import STAGES
from temporal_torchrl.rewards import RewardHeads, TemporalReward

#: Finetuning stages (thesis 3.1.3.1 and 3.1.3.2): 1 from negatives only, 2 with positives too.


class FinetuningLoss(LossModule):
    """A loss that finetunes one of a :class:`~temporal_torchrl.rewards.TemporalReward`'s pairs
    of heads, in the stage its caller sets.

    The loss owns only those heads, so ``torch.optim.Adam(loss.parameters())`` is its optimizer.
    The reward is referenced, not registered as a submodule: its variant, text embeddings, alpha
    and projection are read at every call, so the loss scores the reward the agent receives.
    s_g, the goal image embedding, is a buffer (saved with the loss).

    The stage is not read from the batch: the caller, which knows whether the replay holds
    positives (:attr:`~temporal_torchrl.training.RewardHeadTrainer.stage`), sets it, and the
    loss reads the groups that stage uses (:meth:`groups`): ``"negative"`` in stage 1,
    ``"positive"`` and ``"positive_pair"`` too in stage 2.

    A registered reward's own loss (:func:`~temporal_torchrl.rewards.register_reward`'s
    ``loss``) is a subclass whose ``__init__`` takes ``(reward, goal_image_embedding, *,
    stage)`` and, where it uses them, finetuning settings by name (``delta``, ``l2_margin``,
    ``same_position``); :meth:`from_settings` builds it. Its hyperparameters are the reward's
    options (``self.reward.options``), so a config sets them as ``reward.options.<name>``.

    A loss implements :meth:`terms`, its named terms before they are summed, and :meth:`forward`
    sums them; so a loss "built-in plus one term" is a subclass whose ``terms`` adds its term to
    ``super().terms(tensordict)``, with no copy of the built-in's equations.

    Args:
        reward: the reward whose heads are trained.
        heads: those heads (``reward.positional_heads`` or ``reward.directional_heads``).
        goal_image_embedding: s_g ``[D]``, see :func:`temporal_torchrl.data.goal_image_embedding`.
        stage: 1 or 2 (:data:`STAGES`); :attr:`stage` changes it.
    """

    #: The key of the loss to minimise in the output.
    loss_key: str

    def __init__(self, reward: TemporalReward, heads: RewardHeads, goal_image_embedding: Tensor,
                 *, stage: int) -> None:
        super().__init__()
        self.heads = heads
        self.__dict__["reward"] = reward
        self.register_buffer("goal_image_embedding",
                             torch.as_tensor(goal_image_embedding, dtype=torch.float32).clone())
        self.stage = stage

    @classmethod
    def from_settings(cls, reward: TemporalReward, goal_image_embedding: Tensor, *,
                      stage: int, **settings: Any) -> FinetuningLoss:
        """The loss of ``reward``'s heads, given those of the finetuning ``settings`` (the
        recipe's ``reward.delta``, ``reward.l2_margin``, ``reward.same_position``, by name) that
        its ``__init__`` takes (all of them when it takes ``**kwargs``): how
        :func:`~temporal_torchrl.objectives.finetuning_losses` builds every loss, the built-in
        ones and a registered reward's own."""
        parameters = inspect.signature(cls).parameters
        if not any(parameter.kind is parameter.VAR_KEYWORD
                   for parameter in parameters.values()):
            settings = {key: value for key, value in settings.items() if key in parameters}
        return cls(reward, goal_image_embedding, stage=stage, **settings)

    @property
    def stage(self) -> int:
        """The finetuning stage the loss runs in (:data:`STAGES`), set by its caller."""
        return self._stage

    @stage.setter
    def stage(self, stage: int) -> None:
        if stage not in STAGES or isinstance(stage, bool):
            raise ValueError(f"{type(self).__name__}: stage={stage!r}; expected 1 (negatives "
                             "only) or 2 (positives too: the replay holds a successful "
                             "episode).")
        self._stage = int(stage)

    def groups(self, tensordict: TensorDictBase) -> dict[str, TensorDictBase]:
        """The batch's groups of states that the stage reads, those the batch holds, by name:
        ``negative``, and in stage 2 also ``positive`` and the pair's ``later`` and
        ``earlier``. A term whose group is absent is left out of the loss."""
        names = ("negative", "positive") if self.stage == 2 else ("negative",)
        groups = {name: tensordict[name] for name in names if name in tensordict.keys()}
        pair = tensordict.get("positive_pair", None) if self.stage == 2 else None
        if pair is not None:
            groups.update(later=pair["later"], earlier=pair["earlier"])
        return groups

    def terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The loss's named terms for one batch, before :meth:`forward` sums them: every entry
        named ``loss_*`` is a term (a scalar with gradients into the heads), any other a metric
        passed on as it is (TorchRL's convention for a loss module's output). A term whose
        group is absent from the batch (:meth:`groups`) is left out. Extend a loss by
        overriding this: ``terms = super().terms(tensordict)``, then add a ``loss_*`` entry."""
        raise NotImplementedError(
            f"{type(self).__name__} implements neither terms() nor forward(); a FinetuningLoss "
            "returns its named terms from terms(tensordict) and forward() sums them.")

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Losses for one batch (:meth:`output`): :attr:`loss_key`, the sum of the ``loss_*``
        entries of :meth:`terms` (to minimise), each term detached, the metrics,
        ``stage`` and ``summed_parts``."""
        terms = self.terms(tensordict)
        if self.loss_key in terms:
            raise ValueError(
                f"{type(self).__name__}.terms() returned an entry named {self.loss_key!r}, the "
                "key of the loss's sum; name each term after its part, e.g. 'loss_<part>'.")
        parts = {name: value for name, value in terms.items() if name.startswith("loss_")}
        metrics = {name: value for name, value in terms.items() if name not in parts}
        return self.output(parts, metrics)

    def output(self, parts: dict[str, Tensor],
               extra: dict[str, Tensor] | None = None) -> TensorDict:
        """The loss's output: :attr:`loss_key` the sum of ``parts`` (to minimise), each part
        detached, ``stage``, ``summed_parts`` (how many: 0 when the batch held nothing to score,
        and :attr:`loss_key` is a constant), and ``extra`` (metrics) as given."""
        out = {**(extra or {}), **{name: value.detach() for name, value in parts.items()}}
        # torch.stack(...).sum(), not sum(parts, zero): inductor simplifies one part plus a zero
        # to the part and merges it with the part's detached copy, which loses the gradient.
        out[self.loss_key] = (torch.stack(list(parts.values())).sum() if parts
                              else self.goal_image_embedding.new_zeros(()))
        out["stage"] = torch.tensor(self.stage)
        out["summed_parts"] = torch.tensor(len(parts))
        return TensorDict(out, [])


def joined(tensors: list[Tensor]) -> Tensor:
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
