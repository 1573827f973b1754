"""Episode replay on TorchRL's buffer API: whole episodes, compact embeddings, histories by index.

Layout. An episode of ``T`` transitions is stored as ``T + 1`` consecutive rows of a
:class:`~torchrl.data.LazyTensorStorage`, one row per *state* ``s_0 .. s_T``
(:func:`episode_rows`): row ``t`` holds the observation and embedding of state ``t``, its success
flag, and the action ``a_t`` taken from it (zeros in the last row). Transition ``t`` is the row
pair ``(t, t + 1)``. Each embedding is stored once, and every history the rewards need is index
arithmetic inside the episode:

- ``s_{t+1}``   = row ``t + 1``
- ``s_0``       = row ``t - step_t`` (the episode's first row)
- ``s_{t+1-k}`` = row ``t + 1 - min(t + 1, k)`` (clamped to ``s_0`` at the episode start, as the
  history transform does during collection)
- the window ``s_{t+2-K} .. s_{t+1}`` (d_sequence, ``window_length=K``) = rows
  ``t + 1 - min(t + 1, K - 1 - j)``, ``j = 0 .. K - 1`` (padded with ``s_0`` likewise)

The TorchRL parts:

- :class:`EpisodeWriter` writes each episode contiguously (wrapping to the first row after the
  permanent episodes when the tail is too short) and invalidates every older episode it
  overlaps *as a whole*, so no index arithmetic can reach into a newer episode. TorchRL's
  ``RoundRobinWriter`` splits an episode across the end of the storage and leaves the older
  half of an overwritten one readable.
- :class:`TransitionSampler` draws transitions uniformly over the valid rows, episode starts
  included (``SliceSampler(strict_length=True)`` never gives the first ``k`` steps a full
  history), and returns for each the rows ``[t, t + 1, s_0, s_{t+1-k}, window...]``;
  :class:`TransitionLayout`, the buffer's transform, turns those rows into SAC's transition
  layout, and a :class:`~temporal_torchrl.transforms.TemporalRewardTransform` after it relabels
  ``("next", "reward")`` with the heads as they are now.
- :class:`FinetuningSampler` draws the reward-finetuning groups (negatives, positives, positive
  pairs) from the same storage, through a second buffer on it (``buffer.finetuning``), whose
  transform :class:`FinetuningLayout` names the groups.

Pixels are never stored; embeddings are kept in ``float16`` by default (1024-d: 2 KiB a state),
which puts 500,000 transitions with D = 1024 at about 1.12 GB.

Labels (FuRL's rule, :func:`episode_labels`) are written when an episode is inserted, i.e. when
it has ended: ``+1`` positive, ``-1`` negative, ``0`` unlabelled. They label the states reached by
a step, s_1 .. s_T: the reset frame s_0 is never labelled, as in the reference implementations
(which embed after ``env.step``). With a fixed layout s_0 is the same image in every episode, so
labelling it would sample one state as a positive and as a negative at once.

Permanent episodes (the first ``permanent_episodes`` inserted: stage 2's preloaded experts) sit
at the start of the storage, outside the ring: when the buffer wraps, it wraps to the row after
them, so they are never overwritten however long the run (FuRL keeps its positives in a buffer
of their own for the same reason).

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> T = 6
    >>> episode = TensorDict({
    ...     "observation": torch.randn(T, 39), "embedding": torch.randn(T, 8),
    ...     "action": torch.rand(T, 4), "success": torch.zeros(T, 1, dtype=torch.bool),
    ...     "next": {"observation": torch.randn(T, 39), "embedding": torch.randn(T, 8),
    ...              "success": torch.zeros(T, 1, dtype=torch.bool),
    ...              "terminated": torch.zeros(T, 1, dtype=torch.bool)}}, [T])
    >>> buffer = EpisodeReplayBuffer(capacity=100, history=2)
    >>> _ = buffer.extend(episode_rows(episode))
    >>> batch = buffer.sample(4)
    >>> batch["next", "previous_embedding"].shape
    torch.Size([4, 8])
    >>> buffer.num_transitions, buffer.has_positives
    (6, False)
    >>> sorted(buffer.finetuning.sample(4).keys())
    ['negative']
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers import ImmutableDatasetWriter, Sampler, Writer
from torchrl.data.replay_buffers.storages import Storage
from torchrl.envs.transforms import Compose, Transform

from temporal_torchrl.rewards.temporal import check_window_length

POSITIVE = 1
NEGATIVE = -1
UNLABELLED = 0

#: State-level keys copied from an episode (when present).
STATE_KEYS = ("observation", "embedding")
#: The finetuning groups, in the order :class:`FinetuningSampler` stacks them.
FINETUNING_GROUPS = ("negative", "positive", "positive_pair")


def episode_labels(next_success: torch.Tensor) -> torch.Tensor:
    """FuRL's labels for the ``T`` transitions of one ended episode (int8 ``[T]``).

    ``next_success[t]`` is the success flag after transition ``t``. In a successful episode the
    positive transitions are ``0 .. t*`` (``t*`` the first success) plus the run of consecutive
    success transitions right after ``t*``; the rest is unlabelled. Every transition of a failed
    episode is negative.

    >>> episode_labels(torch.tensor([False, True, True, False, True])).tolist()
    [1, 1, 1, 0, 0]
    >>> episode_labels(torch.tensor([False, False])).tolist()
    [-1, -1]
    """
    success = next_success.reshape(-1).bool()
    labels = torch.zeros(success.shape[0], dtype=torch.int8)
    if not bool(success.any()):
        labels.fill_(NEGATIVE)
        return labels
    first = int(success.int().argmax())
    end = first + 1
    while end < success.shape[0] and bool(success[end]):
        end += 1
    labels[:end] = POSITIVE
    return labels


def episode_rows(episode: TensorDictBase, *,
                 embedding_dtype: torch.dtype = torch.float16) -> TensorDict:
    """The ``T + 1`` stored rows of one ended episode given in ``env.rollout()`` layout ``[T]``.

    Keys: ``observation`` and ``embedding`` (when the episode has them; embeddings in
    ``embedding_dtype``), ``action`` (zeros in the last row), ``success``, ``terminated``,
    ``label`` (:func:`episode_labels`, the reset row unlabelled), ``step`` and ``last``.
    Pixels and every other key are left out.
    """
    if episode.ndim != 1 or episode.shape[0] < 1:
        raise ValueError(f"episode has batch shape {tuple(episode.shape)}; expected one "
                         "unbatched episode [T] with T >= 1 (split batched rollouts first).")
    steps = episode.shape[0]
    rows = {}
    for key in STATE_KEYS:
        if key in episode.keys():
            states = torch.cat([episode[key][:1], episode["next", key]], 0)
            rows[key] = states.to(embedding_dtype if key == "embedding" else torch.float32)
    action = episode["action"].float()
    rows["action"] = torch.cat([action, torch.zeros_like(action[:1])], 0)
    next_success = episode["next", "success"].reshape(steps, 1).bool()
    first_success = (episode["success"][:1].reshape(1, 1).bool() if "success" in episode.keys()
                     else torch.zeros(1, 1, dtype=torch.bool))
    rows["success"] = torch.cat([first_success, next_success], 0)
    terminated = episode.get(("next", "terminated"), torch.zeros(steps, 1, dtype=torch.bool))
    rows["terminated"] = torch.cat([torch.zeros(1, 1, dtype=torch.bool),
                                    terminated.reshape(steps, 1).bool()], 0)
    labels = episode_labels(next_success)
    rows["label"] = torch.cat([torch.full((1,), UNLABELLED, dtype=torch.int8), labels], 0)
    rows["step"] = torch.arange(steps + 1, dtype=torch.int32)
    last = torch.zeros(steps + 1, dtype=torch.bool)
    last[-1] = True
    rows["last"] = last
    return TensorDict(rows, [steps + 1])


class EpisodeStorage(LazyTensorStorage):
    """:class:`~torchrl.data.LazyTensorStorage` whose reads gather rows with ``index_select``.

    A batch reads a few rows per sample (:func:`transition_index`): gathering each column with
    one ``index_select`` over the flattened index is about 6x faster on a CPU than the advanced
    indexing a TensorDict applies by default (0.07 ms against 0.39 ms for 1,024 rows of
    1024-d float16 embeddings), which decides the sampling time of a large buffer.
    """

    def get(self, index: Any) -> Any:
        if not isinstance(index, torch.Tensor) or index.dtype == torch.bool:
            return super().get(index)
        columns = super().get(slice(None))
        flat = index.reshape(-1).to(columns.device)
        gathered = columns.apply(lambda column: column.index_select(0, flat),
                                 batch_size=[flat.numel()])
        return gathered.reshape(index.shape)


class EpisodeWriter(Writer):
    """Writes one episode's rows (:func:`episode_rows`) per ``extend``, contiguously.

    Each write invalidates every older episode it overlaps as a whole, and stamps the rows with
    an ``"episode"`` id. The first ``permanent_episodes`` episodes are written at the start of the
    storage and never overwritten: the ring wraps to the row after them. The writer keeps the
    bookkeeping the samplers read (which rows are valid, and the row sets derived from them,
    recomputed once per written episode, never per sample); ``version`` counts the writes.

    Args:
        permanent_episodes: how many of the first episodes are permanent (stage 2's preloaded
            experts: ``train.preload_positives``).
    """

    def __init__(self, permanent_episodes: int = 0) -> None:
        super().__init__()
        if isinstance(permanent_episodes, bool) or not isinstance(permanent_episodes, int) \
                or permanent_episodes < 0:
            raise ValueError(f"permanent_episodes={permanent_episodes!r}; expected an integer "
                             ">= 0 (the preloaded expert episodes).")
        self.permanent_episodes = permanent_episodes
        self._empty()

    def register_storage(self, storage: Storage) -> None:
        super().register_storage(storage)
        self._valid = torch.zeros(storage.max_size, dtype=torch.bool)

    def _empty(self, empty_write_count: bool = True) -> None:
        self._cursor = 0
        self._permanent_rows = 0
        self._next_episode = 0
        self._write_count = 0
        # episode id -> (first row, number of rows); only episodes still readable are kept.
        self.episodes: dict[int, tuple[int, int]] = {}
        self._keys: set[str] | None = None
        if self._storage is not None:
            self._valid = torch.zeros(self._storage.max_size, dtype=torch.bool)
        self.version = 0
        self._derived = None

    @property
    def capacity(self) -> int:
        return self._storage.max_size

    def add(self, data: Any) -> int:
        raise RuntimeError("EpisodeWriter writes whole episodes: extend the buffer with the rows "
                           "of one episode (episode_rows(rollout)), not with a single row.")

    def extend(self, data: TensorDictBase) -> torch.Tensor:
        length = data.shape[0] if data.ndim == 1 else 0
        if length < 2 or "step" not in data.keys():
            hint = (" It looks like a rollout: insert episode_rows(rollout)."
                    if "next" in data.keys() else "")
            raise ValueError(f"extend takes the rows of one episode (episode_rows(rollout): "
                             f"[T + 1] with T >= 1); got shape {tuple(data.shape)} with keys "
                             f"{sorted(data.keys())}.{hint}")
        keys = set(data.keys()) - {"episode"}
        if self._keys is not None and keys != self._keys:
            raise ValueError(
                f"an episode with keys {sorted(keys)} does not match the buffer's "
                f"{sorted(self._keys)}; every episode must carry the same keys (embed all of "
                "them with the same encoder, or none of them).")
        permanent = self._next_episode < self.permanent_episodes
        if permanent and self._cursor + length > self.capacity:
            raise ValueError(f"permanent episodes fill more than capacity={self.capacity} rows; "
                             "raise the buffer capacity.")
        if length > self.capacity - self._permanent_rows:
            raise ValueError(f"an episode of {length} rows does not fit in capacity="
                             f"{self.capacity} ({self._permanent_rows} rows hold permanent "
                             "episodes); raise the buffer capacity.")
        start = self._cursor if self._cursor + length <= self.capacity else self._permanent_rows
        index = torch.arange(start, start + length)
        self._invalidate_overlapping(start, start + length)
        episode_id = self._next_episode
        data = data.clone(False)
        data["episode"] = torch.full((length,), episode_id, dtype=torch.int64,
                                     device=data.device)
        self._storage.set(index, data)
        self._valid[start:start + length] = True
        self._keys = keys
        self.episodes[episode_id] = (start, length)
        self._next_episode += 1
        self._cursor = start + length
        self._write_count += length
        if permanent:
            self._permanent_rows = self._cursor
        self.version += 1
        self._derived = None
        return index

    def _invalidate_overlapping(self, start: int, stop: int) -> None:
        for episode_id, (first, length) in list(self.episodes.items()):
            if first < stop and start < first + length:
                self._valid[first:first + length] = False
                del self.episodes[episode_id]

    def columns(self) -> TensorDictBase:
        """The stored rows as one TensorDict of views (no copy), rows ``0 .. len - 1``."""
        return self._storage.get(slice(None))

    def rows(self) -> dict[str, torch.Tensor]:
        """The sampleable transitions, cached per write (CPU ``int32`` tensors):
        ``transitions`` (valid rows that are not an episode's last) and their ``steps``."""
        if self._derived is None:
            self._derived = self._derive()
        return self._derived

    def _derive(self) -> dict[str, torch.Tensor]:
        if not self.episodes:
            empty = torch.zeros(0, dtype=torch.int32)
            return {"transitions": empty, "steps": empty}
        columns = self.columns().select("last", "step").cpu()
        # int32 rows and steps: a 1,000,000-row buffer keeps 8 MB of index sets, not 16.
        transitions = torch.nonzero(self._valid[:columns.shape[0]] & ~columns["last"])
        transitions = transitions.reshape(-1).int()
        return {"transitions": transitions, "steps": columns["step"][transitions].int()}

    @property
    def valid(self) -> torch.Tensor:
        """Per storage row: whether it belongs to an episode still stored whole."""
        return self._valid

    @property
    def num_permanent_episodes(self) -> int:
        return min(self._next_episode, self.permanent_episodes)

    def state_dict(self) -> dict[str, Any]:
        first = torch.tensor([first for first, _ in self.episodes.values()], dtype=torch.int64)
        return {"cursor": self._cursor, "permanent_rows": self._permanent_rows,
                "next_episode": self._next_episode, "write_count": self._write_count,
                "valid": self._valid.clone(),
                "episode_ids": torch.tensor(list(self.episodes), dtype=torch.int64),
                "episode_first": first,
                "episode_length": torch.tensor([n for _, n in self.episodes.values()],
                                               dtype=torch.int64),
                "keys": sorted(self._keys) if self._keys is not None else None}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._cursor = state_dict["cursor"]
        self._permanent_rows = state_dict["permanent_rows"]
        self._next_episode = state_dict["next_episode"]
        self._write_count = state_dict["write_count"]
        self._valid = state_dict["valid"].clone()
        self.episodes = {int(i): (int(f), int(n)) for i, f, n in zip(
            state_dict["episode_ids"], state_dict["episode_first"],
            state_dict["episode_length"], strict=True)}
        self._keys = set(state_dict["keys"]) if state_dict["keys"] is not None else None
        self.version += 1
        self._derived = None

    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        torch.save(self.state_dict(), path / "episode_writer.pt")

    def loads(self, path: str | Path) -> None:
        self.load_state_dict(torch.load(Path(path) / "episode_writer.pt", weights_only=True))


def _draw(candidates: torch.Tensor, batch_size: int, what: str) -> torch.Tensor:
    if candidates.numel() == 0:
        raise RuntimeError(f"no {what} stored yet: insert episodes before sampling.")
    return torch.randint(candidates.numel(), (batch_size,))


def _window_rows(rows: torch.Tensor, step: torch.Tensor, window_length: int) -> torch.Tensor:
    """Rows ``rows - min(step, K - 1 - j)``, j = 0 .. K - 1: the window ending at each row,
    never before its episode's first row (``[..., K]``)."""
    offsets = torch.arange(window_length - 1, -1, -1, device=rows.device)
    return rows.unsqueeze(-1) - torch.minimum(offsets, step.unsqueeze(-1))


def state_index(rows: torch.Tensor, step: torch.Tensor, history: int,
                window_length: int | None = None) -> torch.Tensor:
    """The rows a state needs, ``[..., 3 (+ K)]``: ``[s_t, s_0, s_{t-k}, window...]``."""
    rows, step = rows.long(), step.long()
    columns = [rows, rows - step, rows - torch.clamp(step, max=history)]
    index = torch.stack(columns, -1)
    if window_length:
        index = torch.cat([index, _window_rows(rows, step, window_length)], -1)
    return index


def transition_index(rows: torch.Tensor, step: torch.Tensor, history: int,
                     window_length: int | None = None) -> torch.Tensor:
    """The rows a transition from state ``t`` needs, ``[..., 4 (+ K)]``:
    ``[t, t + 1, s_0, s_{t+1-k}, window of s_{t+1}...]``."""
    rows, step = rows.long(), step.long()
    following = rows + 1
    columns = [rows, following, rows - step, following - torch.clamp(step + 1, max=history)]
    index = torch.stack(columns, -1)
    if window_length:
        index = torch.cat([index, _window_rows(following, step + 1, window_length)], -1)
    return index


class _EpisodeRowSampler(Sampler):
    """Shared by the two samplers: they read the :class:`EpisodeWriter`'s row sets."""

    def __init__(self, writer: EpisodeWriter, history: int, window_length: int | None) -> None:
        if history < 1:
            raise ValueError(f"history={history} must be >= 1 (k, the embedding offset).")
        check_window_length(window_length, optional=True)
        self.writer = writer
        self.history = history
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
        history: ``k``, the offset of the previous embedding ``s_{t-k}`` (thesis section 4.3).
        window_length: K: also the rows of the last K embeddings (d_sequence); None: none.
    """

    def sample(self, storage: Storage, batch_size: int) -> tuple[torch.Tensor, dict]:
        rows = self.writer.rows()
        pick = _draw(rows["transitions"], batch_size, "transitions")
        index = transition_index(rows["transitions"][pick], rows["steps"][pick], self.history,
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
        writer, history, window_length: as :class:`TransitionSampler`.
        gap: the positive pairs' lag (``reward.gap``).
        label_window: once positives exist, positives and negatives are drawn from the most
            recent ``label_window`` labelled states of each kind (FuRL's two FIFO buffers of
            20,000 embeddings); None: all of them.
    """

    def __init__(self, writer: EpisodeWriter, history: int, window_length: int | None, *,
                 gap: int = 10, label_window: int | None = 20_000) -> None:
        super().__init__(writer, history, window_length)
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
        index = state_index(torch.stack(anchors), torch.stack(steps), self.history,
                            self.window_length)
        return index, {"groups": groups}


def _embeddings(rows: TensorDictBase, columns: slice | int) -> torch.Tensor:
    return rows["embedding"][..., columns, :].float()


def _to_device(batch: TensorDict, device: torch.device | None) -> TensorDict:
    """``batch`` on ``device``; from the CPU to a GPU through pinned memory, asynchronously."""
    if device is None or batch.device == device:
        return batch
    if batch.device is not None and batch.device.type == "cpu" and device.type == "cuda":
        batch = batch.pin_memory()
    return batch.to(device, non_blocking=True)


class TransitionLayout(Transform):
    """Rows ``[B, 4 (+ K)]`` from :class:`TransitionSampler` -> SAC transitions ``[B]``.

    Keys: ``observation``, ``action``, ``step``, ``episode`` and under ``"next"``:
    ``observation``, ``embedding`` (s_{t+1}), ``initial_embedding`` (s_0),
    ``previous_embedding`` (s_{t+1-k}, s_0 when ``t+1-k <= 0``), with ``window_length``
    ``embedding_window`` (s_{t+2-K} .. s_{t+1}, padded with s_0), ``success``, ``terminated``,
    ``truncated``, ``done`` and ``reward`` (the sparse task reward ``success_{t+1} - 1``, which a
    :class:`~temporal_torchrl.transforms.TemporalRewardTransform` after this one overwrites).
    Embeddings are returned in ``float32``, the batch on ``device`` (None: the storage's).
    """

    def __init__(self, window_length: int | None = None,
                 device: torch.device | str | None = None) -> None:
        super().__init__()
        self.window_length = window_length
        self.device = torch.device(device) if device is not None else None

    def forward(self, rows: TensorDictBase) -> TensorDictBase:
        success = rows["success"][:, 1]
        terminated = rows["terminated"][:, 1]
        truncated = rows["last"][:, 1].unsqueeze(-1)
        following = {"success": success, "terminated": terminated, "truncated": truncated,
                     "done": terminated | truncated, "reward": success.float() - 1.0}
        batch = {"action": rows["action"][:, 0], "step": rows["step"][:, 0].long(),
                 "episode": rows["episode"][:, 0]}
        if "observation" in rows.keys():
            batch["observation"] = rows["observation"][:, 0]
            following["observation"] = rows["observation"][:, 1]
        if "embedding" in rows.keys():
            embeddings = _embeddings(rows, slice(1, None))
            following["embedding"] = embeddings[:, 0]
            following["initial_embedding"] = embeddings[:, 1]
            following["previous_embedding"] = embeddings[:, 2]
            if self.window_length:
                following["embedding_window"] = embeddings[:, 3:]
        batch["next"] = following
        return _to_device(TensorDict(batch, rows.shape[:1], device=rows.device), self.device)


class FinetuningLayout(Transform):
    """Rows ``[G, B, 3 (+ K)]`` from :class:`FinetuningSampler` -> the finetuning batch ``[B]``.

    Sub-TensorDicts ``"negative"``, ``"positive"`` (states) and ``"positive_pair"`` (``"later"``
    s_i and ``"earlier"`` s_{i-gap}), those the sampler drew (``groups``, the sampler's
    :meth:`FinetuningSampler.groups`: the same answer as when it sampled, both read from the
    writer). Each state has ``embedding`` (s_t), ``initial_embedding`` (s_0),
    ``previous_embedding`` (s_{t-k}, clamped to s_0), with ``window_length`` ``embedding_window``
    (s_{t-K+1} .. s_t, padded with s_0), ``label``, ``step`` and ``episode``; the batch on
    ``device`` (None: the storage's).
    """

    def __init__(self, groups: Callable[[], tuple[str, ...]],
                 window_length: int | None = None,
                 device: torch.device | str | None = None) -> None:
        super().__init__()
        self.groups = groups
        self.window_length = window_length
        self.device = torch.device(device) if device is not None else None

    def _states(self, rows: TensorDictBase, embeddings: torch.Tensor) -> TensorDict:
        states = {"embedding": embeddings[:, 0], "initial_embedding": embeddings[:, 1],
                  "previous_embedding": embeddings[:, 2], "label": rows["label"][:, 0],
                  "step": rows["step"][:, 0].long(), "episode": rows["episode"][:, 0]}
        if self.window_length:
            states["embedding_window"] = embeddings[:, 3:]
        return TensorDict(states, rows.shape[:1], device=rows.device)

    def forward(self, rows: TensorDictBase) -> TensorDictBase:
        batch = TensorDict({}, rows.shape[1:2], device=rows.device)
        embeddings = _embeddings(rows, slice(None))  # one conversion for every group
        group = iter(range(rows.shape[0]))

        def states() -> TensorDict:
            index = next(group)
            return self._states(rows[index], embeddings[index])

        for name in self.groups():
            if name == "positive_pair":
                batch[name] = TensorDict({"later": states(), "earlier": states()},
                                         rows.shape[1:2])
            else:
                batch[name] = states()
        return _to_device(batch, self.device)


class EpisodeReplayBuffer(ReplayBuffer):
    """TorchRL :class:`~torchrl.data.ReplayBuffer` of whole episodes (see the module doc).

    ``extend`` takes the rows of one ended episode (:func:`episode_rows`); ``sample`` returns
    SAC transitions with their histories, relabelled by ``reward`` (the heads as they are at
    sampling time) when one is given; ``finetuning.sample`` returns the reward-finetuning batch
    from the same storage.

    Args:
        capacity: number of stored rows; an episode of ``T`` transitions takes ``T + 1`` rows
            (one per state), so 500 transitions per episode use 0.2 % more than ``T`` rows.
        history: ``k``, the offset of the previous embedding ``s_{t-k}`` (thesis section 4.3).
        window_length: K (>= 2): batches also carry ``"embedding_window"``, the last K
            embeddings of each state (the reward's ``window_length``; None: no window).
        label_window, gap: the finetuning sampler's (:class:`FinetuningSampler`).
        permanent_episodes: how many of the first inserted episodes are never overwritten
            (stage 2's preloaded experts).
        reward: relabels SAC batches (a :class:`~temporal_torchrl.rewards.TemporalReward`);
            None: batches keep the sparse task reward.
        batch_size, finetuning_batch_size: default batch sizes of ``sample`` and
            ``finetuning.sample``.
        device: where the storage lives.
        batch_device: where batches are returned (and relabelled): the training device; None:
            the storage's. From a CPU storage to a GPU, batches go through pinned memory.
    """

    def __init__(self, capacity: int, *, history: int = 5, window_length: int | None = None,
                 label_window: int | None = 20_000, gap: int = 10, permanent_episodes: int = 0,
                 reward: torch.nn.Module | None = None, batch_size: int | None = None,
                 finetuning_batch_size: int | None = None,
                 device: torch.device | str = "cpu",
                 batch_device: torch.device | str | None = None) -> None:
        from temporal_torchrl.transforms.reward import TemporalRewardTransform

        if capacity < 2:
            raise ValueError(f"capacity={capacity} must be >= 2 rows (one episode of one step).")
        storage = EpisodeStorage(capacity, device=device)
        writer = EpisodeWriter(permanent_episodes)
        transforms = [TransitionLayout(window_length, batch_device)]
        if reward is not None:
            transforms.append(TemporalRewardTransform(reward))
        super().__init__(storage=storage, writer=writer,
                         sampler=TransitionSampler(writer, history, window_length),
                         transform=Compose(*transforms), batch_size=batch_size)
        finetuning_sampler = FinetuningSampler(writer, history, window_length, gap=gap,
                                               label_window=label_window)
        self.finetuning = ReplayBuffer(
            storage=storage, writer=ImmutableDatasetWriter(), sampler=finetuning_sampler,
            transform=FinetuningLayout(finetuning_sampler.groups, window_length, batch_device),
            batch_size=finetuning_batch_size)

    @property
    def history(self) -> int:
        """k, the offset of s_{t-k}."""
        return self.sampler.history

    @property
    def window_length(self) -> int | None:
        """K, the window batches carry (None: no window)."""
        return self.sampler.window_length

    @property
    def capacity(self) -> int:
        return self.storage.max_size

    @property
    def num_transitions(self) -> int:
        """Number of transitions that can be sampled."""
        return int(self.writer.rows()["transitions"].numel())

    @property
    def num_episodes(self) -> int:
        """Number of episodes still stored whole."""
        return len(self.writer.episodes)

    @property
    def num_positive_states(self) -> int:
        """Number of positive states finetuning samples from (within ``label_window``)."""
        return int(self.finetuning.sampler.candidates()["positive"].numel())

    @property
    def num_permanent_episodes(self) -> int:
        return self.writer.num_permanent_episodes

    @property
    def has_positives(self) -> bool:
        """Whether a stored episode has positive states (the finetuning's stage 2)."""
        return self.num_positive_states > 0

    def memory_bytes(self) -> int:
        """Bytes held by the stored rows and the writer's bookkeeping."""
        stored = 0
        if self.writer.episodes:
            stored = sum(t.numel() * t.element_size() for t in self.storage.get(slice(None))
                         .values(include_nested=True, leaves_only=True))
            # ``get`` views the written rows; the storage holds ``capacity`` of them.
            stored = stored * self.capacity // len(self.storage)
        bookkeeping = [self.writer.valid, *self.writer.rows().values(),
                       *self.finetuning.sampler.candidates().values()]
        return stored + sum(t.numel() * t.element_size() for t in bookkeeping)
