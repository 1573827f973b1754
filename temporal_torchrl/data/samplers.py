"""The replay's samplers: SAC's transitions and the reward finetuning's groups, drawn from the
rows the :class:`~temporal_torchrl.data.EpisodeWriter` keeps valid, with their histories
(:mod:`temporal_torchrl.data.history`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torchrl.data.replay_buffers import Sampler
from torchrl.data.replay_buffers.storages import Storage

from temporal_torchrl.data.episodes import NEGATIVE, POSITIVE
from temporal_torchrl.data.history import state_index, transition_index
from temporal_torchrl.data.writer import EpisodeWriter
from temporal_torchrl.defaults import GAP, LABEL_WINDOW
from temporal_torchrl.rewards.temporal import check_window_length

#: The finetuning groups, in the order :class:`FinetuningSampler` stacks them.
FINETUNING_GROUPS = ("negative", "positive", "positive_pair")


def _draw(candidates: torch.Tensor, batch_size: int, what: str) -> torch.Tensor:
    if candidates.numel() == 0:
        raise RuntimeError(f"no {what} stored yet: insert episodes before sampling.")
    return torch.randint(candidates.numel(), (batch_size,))


class _EpisodeRowSampler(Sampler):
    """Shared by the two samplers: they read the :class:`EpisodeWriter`'s row sets."""

    def __init__(self, writer: EpisodeWriter, k: int, window_length: int | None) -> None:
        if k < 1:
            raise ValueError(f"k={k} must be >= 1 (the offset of s_(t-k)).")
        check_window_length(window_length, optional=True)
        self.writer = writer
        self.k = k
        self.window_length = window_length

    def _empty(self) -> None:
        pass

    def state_dict(self) -> dict[str, Any]:
        return {}  # everything is derived from the writer

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        pass

    def dumps(self, path: str | Path) -> None:
        pass

    def loads(self, path: str | Path) -> None:
        pass


class TransitionSampler(_EpisodeRowSampler):
    """Transitions drawn uniformly (with replacement) over the valid rows, starts included.

    Returns for each the storage rows ``[t, t + 1, s_0, s_{t+1-k}, window...]``
    (:func:`transition_index`), never outside the transition's episode; :class:`TransitionLayout`
    reads them.

    Args:
        writer: the buffer's :class:`EpisodeWriter`.
        k: the offset of the previous embedding ``s_{t-k}`` (thesis section 4.3, ``reward.k``).
        window_length: K: also the rows of the last K embeddings (d_sequence); None: none.
    """

    def sample(self, storage: Storage, batch_size: int) -> tuple[torch.Tensor, dict]:
        rows = self.writer.rows()
        pick = _draw(rows["transitions"], batch_size, "transitions")
        index = transition_index(rows["transitions"][pick], rows["steps"][pick], self.k,
                                 self.window_length)
        return index, {}


class FinetuningSampler(_EpisodeRowSampler):
    """The reward-finetuning batch's states, from the same storage as SAC's transitions.

    Groups (:meth:`groups`, stacked in this order, ``batch_size`` states each), as FuRL and the
    thesis release sample them:

    - ``negative``: negative states (when any is stored); before the first positive (stage 1)
      from every stored negative, afterwards from the ``label_window`` most recent ones.
    - ``positive`` (once a positive episode is stored): FuRL's *valid* positives, the positive
      states ``s_i`` with ``i > gap`` (both stored and labelled ``s_1 ..``, so ``s_{i-gap}`` is
      positive too); only while no positive run is longer than ``gap`` does it fall back to
      every positive state.
    - ``positive_pair``: ``s_i`` drawn from the same valid positives, with ``s_{i-gap}`` of its
      episode.

    Each state comes with the rows of its history (:func:`state_index`);
    :class:`FinetuningLayout` names the groups.

    Args:
        writer, k, window_length: as :class:`TransitionSampler`.
        gap: the positive pairs' lag (``reward.gap``).
        label_window: once positives exist, positives and negatives are drawn from the most
            recent ``label_window`` labelled states of each kind (FuRL's two FIFO buffers of
            20,000 embeddings); None: all of them.
    """

    def __init__(self, writer: EpisodeWriter, k: int, window_length: int | None, *,
                 gap: int = GAP, label_window: int | None = LABEL_WINDOW) -> None:
        super().__init__(writer, k, window_length)
        if gap < 1:
            raise ValueError(f"gap={gap} must be >= 1 (the positive pairs' lag).")
        if label_window is not None and label_window < 1:
            raise ValueError(f"label_window={label_window!r}; expected None (every labelled "
                             "state) or an integer >= 1 (the most recent ones of each kind).")
        self.gap = gap
        self.label_window = label_window
        self._version, self._candidates = -1, {}

    def candidates(self) -> dict[str, torch.Tensor]:
        """Rows and steps (``int32``) of each group's candidates (cached per write)."""
        if self._version != self.writer.version and not self.writer.episodes:
            empty = torch.zeros(0, dtype=torch.int32)
            self._candidates = dict.fromkeys(("positive", "positive_steps", "negative",
                                              "negative_steps", "pair", "pair_steps"), empty)
            self._version = self.writer.version
        if self._version != self.writer.version:
            candidates = {}
            columns = self.writer.columns().select("label", "step", "episode").cpu()
            valid = self.writer.valid[:columns.shape[0]]
            for name, label in (("positive", POSITIVE), ("negative", NEGATIVE)):
                rows = torch.nonzero(valid & (columns["label"] == label)).reshape(-1)
                rows = rows[torch.argsort(columns["episode"][rows], stable=True)]
                candidates[name] = rows.int()
                candidates[name + "_steps"] = columns["step"][rows].int()
            # FuRL's FIFO windows exist only once there are positives: its stage-1 negatives
            # come from the whole replay buffer.
            if self.label_window is not None and candidates["positive"].numel() > 0:
                for name in ("positive", "negative"):
                    candidates[name] = candidates[name][-self.label_window:]
                    candidates[name + "_steps"] = candidates[name + "_steps"][-self.label_window:]
            # FuRL's "valid" positives: states with a partner gap steps earlier in the same
            # positive run; both the pos-neg and the pos-pos terms draw from them.
            later = candidates["positive_steps"] > self.gap
            candidates["pair"] = candidates["positive"][later]
            candidates["pair_steps"] = candidates["positive_steps"][later]
            self._version, self._candidates = self.writer.version, candidates
        return self._candidates

    @property
    def stage(self) -> int:
        """The finetuning's stage (thesis 3.1.3.2): 2 once a stored state is positive, else 1;
        the one place that says so (the loop, the trainer, the losses and the buffer ask here)."""
        return 2 if self.candidates()["positive"].numel() > 0 else 1

    def groups(self) -> tuple[str, ...]:
        """The groups a batch holds now (a subset of :data:`FINETUNING_GROUPS`, in order)."""
        candidates = self.candidates()
        present = {"negative": candidates["negative"].numel() > 0,
                   "positive": candidates["positive"].numel() > 0}
        present["positive_pair"] = present["positive"] and candidates["pair"].numel() > 0
        return tuple(name for name in FINETUNING_GROUPS if present[name])

    def sample(self, storage: Storage, batch_size: int) -> tuple[torch.Tensor, dict]:
        candidates, groups = self.candidates(), self.groups()
        if not groups:
            raise RuntimeError("no labelled states stored yet: insert episodes before sampling.")
        anchors, steps = [], []
        for name in groups:
            source = ("pair" if name == "positive_pair" or (name == "positive" and candidates[
                "pair"].numel() > 0) else name)
            pick = _draw(candidates[source], batch_size, f"{name} states")
            anchors.append(candidates[source][pick])
            steps.append(candidates[source + "_steps"][pick])
            if name == "positive_pair":
                anchors.append(anchors[-1] - self.gap)
                steps.append(steps[-1] - self.gap)
        index = state_index(torch.stack(anchors), torch.stack(steps), self.k,
                            self.window_length)
        return index, {"groups": groups}
