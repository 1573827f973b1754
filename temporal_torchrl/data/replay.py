"""Episode replay buffer: whole episodes, compact embeddings, sub-trajectory sampling by index.

Layout. An episode of ``T`` transitions is stored as ``T + 1`` consecutive rows of a TorchRL
:class:`~torchrl.data.LazyTensorStorage`, one row per *state* ``s_0 .. s_T``: row ``t`` holds the
observation and embedding of state ``t``, its success flag, and the action ``a_t`` taken from it
(zeros in the last row). Transition ``t`` is the row pair ``(t, t + 1)``. So each embedding is
stored once, and every history the rewards need is index arithmetic inside the episode:

- ``s_{t+1}``   = row ``t + 1``
- ``s_0``       = row ``t - step_t`` (the episode's first row)
- ``s_{t+1-k}`` = row ``t + 1 - min(t + 1, k)`` (clamped to ``s_0`` at the episode start, as the
  history transform does during collection)
- the window ``s_{t+2-K} .. s_{t+1}`` (d_sequence, with ``window_length=K``) = rows
  ``t + 1 - min(t + 1, K - 1 - j)``, ``j = 0 .. K - 1`` (padded with ``s_0`` likewise)

Pixels are never stored; embeddings are kept in ``float16`` by default (1024-d: 2 KiB a state),
which puts 500,000 transitions with D = 1024 at about 1.12 GB.

Why not TorchRL's writer and samplers as they are: ``RoundRobinWriter`` splits an episode across
the end of the storage and leaves the older half of an overwritten episode readable, so a
lagged index could land in a newer episode; ``SliceSampler(strict_length=True)`` never samples
the first ``k`` steps of an episode with a full history window. This class therefore writes
each episode contiguously (wrapping to row 0 when the tail is too short), invalidates every
older episode it overlaps *as a whole*, and samples uniformly over valid rows with cached index
sets, using ``LazyTensorStorage`` for the memory itself.

Labels (FuRL's rule, :func:`episode_labels`) are written when an episode is inserted, i.e. when
it has ended: ``+1`` positive, ``-1`` negative, ``0`` unlabelled. They label the states reached by
a step, s_1 .. s_T: the reset frame s_0 is never labelled, as in the reference implementations
(which embed after ``env.step``). With a fixed layout s_0 is the same image in every episode, so
labelling it would sample one state as a positive and as a negative at once.

Permanent episodes (``extend(..., permanent=True)``, stage 2's preloaded experts) are written
first and kept apart from the ring: when the buffer wraps, it wraps to the row after them, so
they are never overwritten, however long the run (FuRL keeps its positives in a buffer of their
own for the same reason).

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
    >>> _ = buffer.extend(episode)
    >>> batch = buffer.sample(4)
    >>> batch["next", "previous_embedding"].shape
    torch.Size([4, 8])
    >>> buffer.num_transitions, buffer.has_positives
    (6, False)
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import LazyTensorStorage

POSITIVE = 1
NEGATIVE = -1
UNLABELLED = 0

# State-level keys copied from an episode (when present), and their stored dtype.
_STATE_KEYS = ("observation", "embedding")


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


class EpisodeReplayBuffer:
    """Whole-episode replay buffer with index-derived embedding histories (see module doc).

    Args:
        capacity: number of stored rows; an episode of ``T`` transitions takes ``T + 1`` rows
            (one per state), so 500 transitions per episode use 0.2 % more than ``T`` rows.
        history: ``k``, the offset of the previous embedding ``s_{t-k}`` (thesis section 4.3).
        embedding_dtype: storage dtype of the embeddings (``float16`` halves the memory; batches
            are returned in ``float32``).
        label_window: positives and negatives are sampled from the most recent
            ``label_window`` labelled states of each kind (FuRL's two FIFO buffers of 20,000
            embeddings); ``None`` uses all of them.
        window_length: K (>= 2): batches also carry ``"embedding_window"``, the last K
            embeddings of each state (``reward.window_length``; None: no window, the default).
    """

    def __init__(self, capacity: int, *, history: int = 5,
                 embedding_dtype: torch.dtype = torch.float16,
                 label_window: int | None = 20_000, window_length: int | None = None) -> None:
        if capacity < 2:
            raise ValueError(f"capacity={capacity} must be >= 2 rows (one episode of one step).")
        if history < 1:
            raise ValueError(f"history={history} must be >= 1 (k, the embedding offset).")
        if window_length is not None and (isinstance(window_length, bool)
                                          or not isinstance(window_length, int)
                                          or window_length < 2):
            raise ValueError(f"window_length={window_length!r}; expected None or an integer "
                             ">= 2 (the K embeddings s_(t-K+1) .. s_t).")
        self.capacity = capacity
        self.history = history
        self.window_length = window_length
        self.embedding_dtype = embedding_dtype
        self.label_window = label_window
        self._storage = LazyTensorStorage(capacity)
        self._cursor = 0
        self._next_episode = 0
        # episode id -> (first row, number of rows); only episodes still readable are kept.
        self._episodes: dict[int, tuple[int, int]] = {}
        self._positive_episodes = 0
        self._permanent_episodes = 0
        self._permanent_rows = 0
        self._refresh_indices()

    # ------------------------------------------------------------------ writing
    def episode_rows(self, episode: TensorDictBase) -> TensorDict:
        """The ``T + 1`` compact rows of an episode given in ``env.rollout()`` layout ``[T]``."""
        if episode.ndim != 1 or episode.shape[0] < 1:
            raise ValueError(f"episode has batch shape {tuple(episode.shape)}; expected one "
                             "unbatched episode [T] with T >= 1 (split batched rollouts first).")
        steps = episode.shape[0]
        rows = {}
        for key in _STATE_KEYS:
            if key in episode.keys():
                states = torch.cat([episode[key][:1], episode["next", key]], 0)
                rows[key] = states.to(self.embedding_dtype if key == "embedding"
                                      else torch.float32)
        action = episode["action"].float()
        rows["action"] = torch.cat([action, torch.zeros_like(action[:1])], 0)
        next_success = episode["next", "success"].reshape(steps, 1).bool()
        first_success = (episode["success"][:1].reshape(1, 1).bool() if "success" in
                         episode.keys() else torch.zeros(1, 1, dtype=torch.bool))
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

    def extend(self, episode: TensorDictBase, *, permanent: bool = False) -> TensorDict:
        """Insert one ended episode (``env.rollout()`` layout ``[T]``, pixels ignored).

        Returns its compact rows, which :meth:`extend_rows` accepts (e.g. to rebuild the buffer
        from saved episodes when a run resumes). ``permanent``: never overwritten (see the
        module docstring); only before any other episode.
        """
        rows = self.episode_rows(episode)
        self.extend_rows(rows, permanent=permanent)
        return rows

    def extend_rows(self, rows: TensorDictBase, *, permanent: bool = False) -> int:
        """Insert the compact rows of one episode; returns its episode id."""
        length = rows.shape[0]
        if permanent and self._next_episode > self._permanent_episodes:
            raise ValueError("permanent episodes must be inserted before any other episode "
                             "(they sit at the start of the storage, outside the ring).")
        free = self.capacity - self._permanent_rows
        if length > free:
            raise ValueError(f"an episode of {length} rows does not fit in capacity="
                             f"{self.capacity} ({self._permanent_rows} rows hold permanent "
                             "episodes); raise the buffer capacity.")
        if self._storage.initialized:
            stored = set(self._storage._storage.keys()) - {"episode", "valid"}
            if set(rows.keys()) != stored:
                raise ValueError(
                    f"an episode with keys {sorted(rows.keys())} does not match the buffer's "
                    f"{sorted(stored)}; every episode must carry the same keys (embed all of "
                    "them with the same encoder, or none of them).")
        if permanent and self._cursor + length > self.capacity:
            raise ValueError(f"permanent episodes fill more than capacity={self.capacity} rows; "
                             "raise the buffer capacity.")
        start = (self._cursor if self._cursor + length <= self.capacity
                 else self._permanent_rows)
        self._invalidate_overlapping(start, start + length)
        episode_id = self._next_episode
        rows = rows.clone(False)
        rows["episode"] = torch.full((length,), episode_id, dtype=torch.int64)
        rows["valid"] = torch.ones(length, dtype=torch.bool)
        first_write = not self._storage.initialized
        self._storage.set(torch.arange(start, start + length), rows)
        if first_write:
            # The lazily allocated storage is uninitialised memory: only written rows are valid.
            self._column("valid")[start + length:] = False
        self._episodes[episode_id] = (start, length)
        self._positive_episodes += bool((rows["label"] == POSITIVE).any())
        self._next_episode += 1
        self._cursor = start + length
        if permanent:
            self._permanent_episodes += 1
            self._permanent_rows = self._cursor
        self._refresh_indices()
        return episode_id

    def _invalidate_overlapping(self, start: int, stop: int) -> None:
        # Whole episodes go, so no index arithmetic can reach into a newer episode.
        for episode_id, (first, length) in list(self._episodes.items()):
            if first < stop and start < first + length:
                self._column("valid")[first:first + length] = False
                if bool((self._column("label")[first:first + length] == POSITIVE).any()):
                    self._positive_episodes -= 1
                del self._episodes[episode_id]

    def _column(self, key: str) -> torch.Tensor:
        # The storage's TensorDict, read column by column: gathering a few keys for a batch is
        # much cheaper than ``storage.get(index)``, which gathers every key.
        return self._storage._storage.get(key)

    def _refresh_indices(self) -> None:
        """Recompute the sampleable index sets (once per inserted episode, never per sample)."""
        empty = torch.zeros(0, dtype=torch.int64)
        if not self._episodes:
            self._transitions = self._positives = self._negatives = empty
            return
        valid = self._column("valid")
        self._transitions = torch.nonzero(valid & ~self._column("last")).reshape(-1)
        label = self._column("label")
        self._positives = self._recent(torch.nonzero(valid & (label == POSITIVE)).reshape(-1))
        self._negatives = self._recent(torch.nonzero(valid & (label == NEGATIVE)).reshape(-1))

    def _recent(self, rows: torch.Tensor) -> torch.Tensor:
        if self.label_window is None or rows.numel() <= self.label_window:
            return rows
        order = torch.argsort(self._column("episode")[rows], stable=True)
        return rows[order[-self.label_window:]]

    # ------------------------------------------------------------------ reading
    @property
    def num_transitions(self) -> int:
        """Number of transitions that can be sampled."""
        return int(self._transitions.numel())

    @property
    def num_episodes(self) -> int:
        """Number of episodes still stored whole."""
        return len(self._episodes)

    @property
    def num_positive_states(self) -> int:
        """Number of positive states finetuning samples from (within ``label_window``)."""
        return int(self._positives.numel())

    @property
    def num_permanent_episodes(self) -> int:
        """Number of permanent episodes (never overwritten)."""
        return self._permanent_episodes

    @property
    def has_positives(self) -> bool:
        """Whether a stored episode has positive steps (the finetuning's stage 2)."""
        return self._positive_episodes > 0

    def __len__(self) -> int:
        return self.num_transitions

    def _embedding(self, rows: torch.Tensor) -> torch.Tensor:
        return self._column("embedding")[rows].float()

    def _has(self, key: str) -> bool:
        return bool(self._episodes) and key in self._storage._storage.keys()

    def _window(self, rows: torch.Tensor, step: torch.Tensor) -> torch.Tensor:
        """The embeddings of rows ``rows - min(step, K - 1 - j)``, j = 0 .. K - 1: ``[B, K, D]``,
        the window ending at each row, never before its episode's first row."""
        offsets = torch.arange(self.window_length - 1, -1, -1)
        return self._embedding(rows.unsqueeze(-1) - torch.minimum(offsets, step.unsqueeze(-1)))

    def transitions_at(self, rows: torch.Tensor) -> TensorDict:
        """SAC transitions starting at storage ``rows`` (each row a state ``t`` with ``t < T``).

        Keys: ``observation``, ``action``, ``step``, ``episode`` and under ``"next"``:
        ``observation``, ``embedding`` (s_{t+1}), ``initial_embedding`` (s_0),
        ``previous_embedding`` (s_{t+1-k}, s_0 when ``t+1-k <= 0``), with ``window_length``
        ``embedding_window`` (s_{t+2-K} .. s_{t+1}, padded with s_0), ``success``,
        ``terminated``, ``truncated``, ``done`` and ``reward`` (the sparse task reward
        ``success_{t+1} - 1``, to be overwritten by the reward transform).
        """
        step = self._column("step")[rows].long()
        following = rows + 1
        success = self._column("success")[following]
        terminated = self._column("terminated")[following]
        truncated = self._column("last")[following].unsqueeze(-1)
        nxt = {"success": success, "terminated": terminated, "truncated": truncated,
               "done": terminated | truncated, "reward": success.float() - 1.0}
        batch = {"action": self._column("action")[rows], "step": step,
                 "episode": self._column("episode")[rows]}
        if self._has("observation"):
            batch["observation"] = self._column("observation")[rows]
            nxt["observation"] = self._column("observation")[following]
        if self._has("embedding"):
            nxt["embedding"] = self._embedding(following)
            nxt["initial_embedding"] = self._embedding(rows - step)
            nxt["previous_embedding"] = self._embedding(
                following - torch.clamp(step + 1, max=self.history))
            if self.window_length:
                nxt["embedding_window"] = self._window(following, step + 1)
        batch["next"] = nxt
        return TensorDict(batch, [rows.shape[0]])

    def states_at(self, rows: torch.Tensor) -> TensorDict:
        """Embedding states at storage ``rows`` with their history, label, step and episode.

        Keys: ``embedding`` (s_t), ``initial_embedding`` (s_0), ``previous_embedding``
        (s_{t-k}, clamped to s_0), with ``window_length`` ``embedding_window``
        (s_{t-K+1} .. s_t, padded with s_0), ``label``, ``step``, ``episode``.
        """
        step = self._column("step")[rows].long()
        states = TensorDict({
            "embedding": self._embedding(rows),
            "initial_embedding": self._embedding(rows - step),
            "previous_embedding": self._embedding(rows - torch.clamp(step, max=self.history)),
            "label": self._column("label")[rows],
            "step": step,
            "episode": self._column("episode")[rows],
        }, [rows.shape[0]])
        if self.window_length:
            states["embedding_window"] = self._window(rows, step)
        return states

    @staticmethod
    def _draw(candidates: torch.Tensor, batch_size: int, what: str) -> torch.Tensor:
        if candidates.numel() == 0:
            raise RuntimeError(f"no {what} stored yet: insert episodes before sampling.")
        return candidates[torch.randint(candidates.numel(), (batch_size,))]

    def sample(self, batch_size: int) -> TensorDict:
        """``batch_size`` transitions drawn uniformly (with replacement), starts included."""
        return self.transitions_at(self._draw(self._transitions, batch_size, "transitions"))

    def sample_states(self, batch_size: int, label: int) -> TensorDict:
        """States with ``label`` (``POSITIVE`` or ``NEGATIVE``) and their histories."""
        candidates = self._positives if label == POSITIVE else self._negatives
        name = "positive states" if label == POSITIVE else "negative states"
        return self.states_at(self._draw(candidates, batch_size, name))

    def sample_positive_pairs(self, batch_size: int, gap: int = 10) -> TensorDict | None:
        """Pairs ``(s_i, s_{i-gap})`` from one positive episode (both positive), or ``None``.

        Returns a TensorDict with sub-TensorDicts ``"later"`` (s_i) and ``"earlier"``
        (s_{i-gap}); positives run from step 1 (s_0 is unlabelled), so ``i - gap >= 1`` keeps
        both in the same positive run.
        """
        candidates = self._positives[self._column("step")[self._positives] > gap]
        if candidates.numel() == 0:
            return None
        later = self._draw(candidates, batch_size, "positive pairs")
        return TensorDict({"later": self.states_at(later),
                           "earlier": self.states_at(later - gap)}, [batch_size])

    def sample_finetuning(self, batch_size: int, gap: int = 10) -> TensorDict:
        """One batch for the reward-finetuning losses.

        Always ``"negative"`` states (when any are stored); once a positive episode is stored
        (stage 2) also ``"positive"`` states and, when some positive run is longer than
        ``gap``, ``"positive_pair"`` (see :meth:`sample_positive_pairs`).
        """
        batch = TensorDict({}, [batch_size])
        if self._negatives.numel():
            batch["negative"] = self.sample_states(batch_size, NEGATIVE)
        if self.has_positives and self._positives.numel():
            batch["positive"] = self.sample_states(batch_size, POSITIVE)
            pairs = self.sample_positive_pairs(batch_size, gap)
            if pairs is not None:
                batch["positive_pair"] = pairs
        return batch

    def memory_bytes(self) -> int:
        """Bytes held by the stored rows and the cached index sets."""
        stored = 0
        if self._episodes:
            stored = sum(t.numel() * t.element_size()
                         for t in self._storage._storage.values(include_nested=True,
                                                                leaves_only=True))
        cached = (self._transitions, self._positives, self._negatives)
        return stored + sum(t.numel() * t.element_size() for t in cached)
