"""Section ``replay``: replay sampling and memory.

Sampling 256 transitions with their histories at 500,000 transitions (D = 1024; ``--smoke``:
fewer) against TorchRL's ``SliceSampler(slice_len=2)`` on the same float16 embeddings; a stage-2
finetuning batch; the replay memory against storing s_t and s_{t+1} in float32.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, SliceSampler, TensorDictReplayBuffer

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from training.common import ACTION_DIM, OBSERVATION_DIM, Budget, synthetic_episode


def filled_buffers(transitions: int, dim: int = 1024, episode_length: int = 500
                   ) -> tuple[EpisodeReplayBuffer, TensorDictReplayBuffer]:
    """The project's buffer and a TorchRL SliceSampler buffer, both with ``transitions``."""
    episodes = transitions // episode_length
    ours = EpisodeReplayBuffer(capacity=episodes * (episode_length + 1), k=5,
                               permanent_episodes=1)
    reference = TensorDictReplayBuffer(
        storage=LazyTensorStorage(transitions),
        sampler=SliceSampler(slice_len=2, traj_key="episode", strict_length=True,
                             truncated_key=None), batch_size=512)
    done = torch.zeros(episode_length, 1, dtype=torch.bool)
    done[-1] = True
    for index in range(episodes):  # the first one successful: finetuning has every group
        episode = synthetic_episode(episode_length, dim, 400 if index == 0 else None)
        ours.extend(episode_rows(episode))
        flat = TensorDict({
            "observation": episode["observation"], "action": episode["action"],
            "episode": torch.full((episode_length,), index),
            "next": {"observation": episode["next", "observation"],
                     "embedding": episode["next", "embedding"].half(),
                     "done": done, "terminated": torch.zeros_like(done)}}, [episode_length])
        reference.extend(flat)
    return ours, reference


def replay_rows(budget: Budget) -> list[dict]:
    """Sampling and finetuning batches from :func:`filled_buffers` at
    ``budget.replay_transitions``, and the project buffer's memory."""
    transitions = budget.replay_transitions
    ours, reference = filled_buffers(transitions)
    ours_seconds = budget.seconds_per_call(lambda: ours.sample(256), 0.5)
    reference_seconds = budget.seconds_per_call(lambda: reference.sample(), 0.5)
    finetuning_seconds = budget.seconds_per_call(lambda: ours.finetuning.sample(256), 0.5)
    naive = transitions * (2 * 1024 * 4 + 2 * OBSERVATION_DIM * 4 + ACTION_DIM * 4 + 4)
    slice_reference = "SliceSampler(slice_len=2), float16 embeddings"
    at = f"{transitions // 1000}k"
    return [
        {"measure": f"sample 256 transitions + histories at {at} (ms)",
         "project": 1000 * ours_seconds, "reference": 1000 * reference_seconds,
         "reference is": slice_reference, "ratio": ours_seconds / reference_seconds},
        {"measure": f"finetuning batch (256 negatives, positives, pairs) at {at} (ms)",
         "project": 1000 * finetuning_seconds, "reference": 1000 * reference_seconds,
         "reference is": slice_reference, "ratio": finetuning_seconds / reference_seconds},
        {"measure": f"replay memory at {at} transitions, D=1024 (GB)",
         "project": ours.memory_bytes() / 1e9, "reference": naive / 1e9,
         "reference is": "s_t and s_t+1 as float32 (computed)",
         "ratio": ours.memory_bytes() / naive},
    ]
