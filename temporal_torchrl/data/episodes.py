"""An ended episode as the replay buffer stores it: FuRL's labels and the rows of its states.

An episode of ``T`` transitions is ``T + 1`` rows, one per *state* ``s_0 .. s_T``
(:func:`episode_rows`): row ``t`` holds the observation and embedding of state ``t``, its success
flag, and the action ``a_t`` taken from it (zeros in the last row). Labels (FuRL's rule,
:func:`episode_labels`) are written when an episode is inserted, i.e. when it has ended: ``+1``
positive, ``-1`` negative, ``0`` unlabelled. They label the states reached by a step,
s_1 .. s_T: the reset frame s_0 is never labelled, as in the reference implementations (which
embed after ``env.step``). With a fixed layout s_0 is the same image in every episode, so
labelling it would sample one state as a positive and as a negative at once.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase

POSITIVE = 1
NEGATIVE = -1
UNLABELLED = 0

#: State-level keys copied from an episode (when present).
STATE_KEYS = ("observation", "embedding")


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
