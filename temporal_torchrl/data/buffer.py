"""Episode replay on TorchRL's buffer API: whole episodes, compact embeddings, histories by index.

One module per TorchRL part: :mod:`~temporal_torchrl.data.episodes` (rows, labels),
:mod:`~temporal_torchrl.data.storage`, :mod:`~temporal_torchrl.data.writer`,
:mod:`~temporal_torchrl.data.history` (the index arithmetic),
:mod:`~temporal_torchrl.data.samplers`, :mod:`~temporal_torchrl.data.layouts` and this buffer,
which composes them.

Layout. An episode of ``T`` transitions is stored as ``T + 1`` consecutive rows of the storage,
one row per *state* (:func:`~temporal_torchrl.data.episode_rows`); transition ``t`` is the row
pair ``(t, t + 1)``. Each embedding is stored once, and every history the rewards need (s_0,
s_{t+1-k}, the window) is index arithmetic inside the episode
(:mod:`~temporal_torchrl.data.history`).

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

Permanent episodes (the first ``permanent_episodes`` inserted: stage 2's preloaded experts) sit
at the start of the storage, outside the ring: when the buffer wraps, it wraps to the row after
them, so they are never overwritten however long the run (FuRL keeps its positives in a buffer
of their own for the same reason).

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from temporal_torchrl.data import episode_rows
    >>> T = 6
    >>> episode = TensorDict({
    ...     "observation": torch.randn(T, 39), "embedding": torch.randn(T, 8),
    ...     "action": torch.rand(T, 4), "success": torch.zeros(T, 1, dtype=torch.bool),
    ...     "next": {"observation": torch.randn(T, 39), "embedding": torch.randn(T, 8),
    ...              "success": torch.zeros(T, 1, dtype=torch.bool),
    ...              "terminated": torch.zeros(T, 1, dtype=torch.bool)}}, [T])
    >>> buffer = EpisodeReplayBuffer(capacity=100, k=2)
    >>> _ = buffer.extend(episode_rows(episode))
    >>> batch = buffer.sample(4)
    >>> batch["next", "previous_embedding"].shape
    torch.Size([4, 8])
    >>> buffer.num_transitions, buffer.stage  # no positive episode yet: stage 1
    (6, 1)
    >>> sorted(buffer.finetuning.sample(4).keys())
    ['negative']
"""

from __future__ import annotations

import warnings

import torch
from torchrl.data import ReplayBuffer
from torchrl.data.replay_buffers import ImmutableDatasetWriter
from torchrl.envs.transforms import Compose

from temporal_torchrl.data.layouts import FinetuningLayout, TransitionLayout
from temporal_torchrl.data.samplers import FinetuningSampler, TransitionSampler
from temporal_torchrl.data.storage import EpisodeStorage
from temporal_torchrl.data.writer import EpisodeWriter
from temporal_torchrl.defaults import GAP, LABEL_WINDOW
from temporal_torchrl.rewards.temporal import (
    TemporalReward,
    renamed_k,
    resolve_k,
    resolve_window,
)


class EpisodeReplayBuffer(ReplayBuffer):
    """TorchRL :class:`~torchrl.data.ReplayBuffer` of whole episodes (see the module doc).

    ``extend`` takes the rows of one ended episode (:func:`episode_rows`); ``sample`` returns
    SAC transitions with their histories, relabelled by ``reward`` (the heads as they are at
    sampling time) when one is given; ``finetuning.sample`` returns the reward-finetuning batch
    from the same storage.

    Args:
        capacity: number of stored rows; an episode of ``T`` transitions takes ``T + 1`` rows
            (one per state), so 500 transitions per episode use 0.2 % more than ``T`` rows.
        k: the offset of the previous embedding ``s_{t-k}`` (thesis section 4.3, ``reward.k``).
            With a ``reward`` leave it out: k is the reward's ``k``, the one the env's history
            transform uses, and a different value is refused (the relabelled batches would read
            another s_{t-k} than the env wrote). Without a reward, default
            :data:`~temporal_torchrl.defaults.K`.
        window_length: K (>= 2): batches also carry ``"embedding_window"``, the last K
            embeddings of each state (None: no window). With a ``reward`` leave it out, as k:
            it is the reward's ``window_length``, and a different value is refused.
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
        history: the deprecated name of ``k`` (a FutureWarning; removed in the next release).
    """

    def __init__(self, capacity: int, *, k: int | None = None,
                 window_length: int | None = None, label_window: int | None = LABEL_WINDOW,
                 gap: int = GAP, permanent_episodes: int = 0,
                 reward: TemporalReward | None = None, batch_size: int | None = None,
                 finetuning_batch_size: int | None = None,
                 device: torch.device | str = "cpu",
                 batch_device: torch.device | str | None = None,
                 history: int | None = None) -> None:
        from temporal_torchrl.transforms.reward import TemporalRewardTransform

        if capacity < 2:
            raise ValueError(f"capacity={capacity} must be >= 2 rows (one episode of one step).")
        k = resolve_k(renamed_k(k, history, "EpisodeReplayBuffer"), reward,
                      "EpisodeReplayBuffer")
        window_length = resolve_window(window_length, reward, "EpisodeReplayBuffer")
        storage = EpisodeStorage(capacity, device=device)
        writer = EpisodeWriter(permanent_episodes)
        transforms = [TransitionLayout(window_length, batch_device)]
        if reward is not None:
            transforms.append(TemporalRewardTransform(reward))
        super().__init__(storage=storage, writer=writer,
                         sampler=TransitionSampler(writer, k, window_length),
                         transform=Compose(*transforms), batch_size=batch_size)
        finetuning_sampler = FinetuningSampler(writer, k, window_length, gap=gap,
                                               label_window=label_window)
        self.finetuning = ReplayBuffer(
            storage=storage, writer=ImmutableDatasetWriter(), sampler=finetuning_sampler,
            transform=FinetuningLayout(finetuning_sampler.groups, window_length, batch_device),
            batch_size=finetuning_batch_size)

    @property
    def k(self) -> int:
        """k, the offset of s_{t-k} (``reward.k``)."""
        return self.sampler.k

    @property
    def history(self) -> int:
        """Deprecated name of :attr:`k` (a FutureWarning; removed in the next release)."""
        warnings.warn("EpisodeReplayBuffer.history is deprecated and will be removed in the next "
                      "release; read .k (the offset of s_(t-k), reward.k).", FutureWarning,
                      stacklevel=2)
        return self.k

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
    def stage(self) -> int:
        """The finetuning's stage (:attr:`FinetuningSampler.stage`)."""
        return self.finetuning.sampler.stage

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
