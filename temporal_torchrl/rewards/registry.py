"""The reward registry: one dict, :data:`REWARDS`, of every registered reward.

Every reward, built-in or a researcher's own, is added with :func:`register_reward`, which records
under its name a :class:`RegisteredReward`: the function, its kind (positional or directional),
what its image head reads and the finetuning objective that trains its heads.
:data:`POSITIONAL`, :data:`DIRECTIONAL`, :data:`IMAGE_INPUTS` and :data:`OBJECTIVES` are read-only
views of that one dict, so they cannot fall out of step with it.
:func:`~temporal_torchrl.rewards.heads.heads_input_dims` and
:class:`~temporal_torchrl.rewards.TemporalReward` build the heads from the record, so a
registered name works everywhere a built-in does. The built-ins register themselves at the end of
:mod:`~temporal_torchrl.rewards.positional`, :mod:`~temporal_torchrl.rewards.directional` and
:mod:`~temporal_torchrl.rewards.certainty`.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from torch import Tensor

from temporal_torchrl.defaults import ALPHA, PROJECTION

#: A reward function; see :func:`register_reward` for the signature it must follow.
RewardFunction = Callable[..., Tensor]

#: Reward kinds: a value of the position (positional) or of the direction (directional).
KINDS = ("positional", "directional")
#: What an image head can read: one embedding ``[D]``, the concatenation of a position part and a
#: direction part ``[2 D]``, a sequence of such concatenations built from the window of the last
#: K embeddings (``"window"``: ``[K - 1, 2 D]``, read by a sequence encoder), or nothing (None: a
#: zero-shot reward without heads).
IMAGE_LAYOUTS = ("embedding", "concatenated", "window", None)
#: Finetuning objectives, by the loss that trains the heads: FuRL's ranking losses (positional
#: rewards), the thesis's directional loss, and the squared error to a certainty target (beyond
#: the thesis, section 6.4 proposal); see :mod:`temporal_torchrl.objectives`.
OBJECTIVES_BY_KIND = {"positional": ("ranking",), "directional": ("directional", "certainty")}

# Every keyword a reward function is called with (TemporalReward and the finetuning losses).
_CALL_KEYWORDS = {"s0": None, "s_prev": None, "g": None, "b": None, "alpha": ALPHA,
                  "projection": PROJECTION, "position": None, "window": None}
_SIGNATURE = (f"fn(heads, s, *, g, b, s0=None, s_prev=None, alpha={ALPHA}, position=None, "
              f"projection={PROJECTION!r}, window=None, **unused)")


@dataclass(frozen=True)
class RegisteredReward:
    """One entry of :data:`REWARDS` (see :func:`register_reward` for each field's values).

    Attributes:
        function: the reward function.
        kind: ``"positional"`` or ``"directional"`` (:data:`KINDS`).
        image_input: what the image head reads (:data:`IMAGE_LAYOUTS`).
        objective: the finetuning objective of its heads (:data:`OBJECTIVES_BY_KIND`).
    """

    function: RewardFunction
    kind: str
    image_input: str | None
    objective: str


#: Every registered reward by name, in the order of registration.
REWARDS: dict[str, RegisteredReward] = {}


class RegistryView(Mapping[str, Any]):
    """A read-only view of one field of :data:`REWARDS`, for the rewards of one kind or all.

    Args:
        name: the view's name, for its messages.
        field: the :class:`RegisteredReward` attribute it maps each name to.
        kind: only rewards of this kind (:data:`KINDS`); None: every reward.
    """

    def __init__(self, name: str, field: str, kind: str | None = None) -> None:
        self._name, self._field, self._kind = name, field, kind

    def __getitem__(self, name: str) -> Any:
        reward = REWARDS.get(name)
        if reward is None or self._kind not in (None, reward.kind):
            raise KeyError(name)
        return getattr(reward, self._field)

    def __iter__(self) -> Iterator[str]:
        return (name for name, reward in REWARDS.items() if self._kind in (None, reward.kind))

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __setitem__(self, name: str, value: Any) -> None:
        kind = self._kind or "positional"
        raise TypeError(f"{self._name} is a read-only view of the reward registry; add {name!r} "
                        f"with register_reward({name!r}, fn, kind={kind!r}, "
                        "image_input='embedding' | 'concatenated' | 'window' | None).")

    def __repr__(self) -> str:
        return f"{self._name}({dict(self)!r})"


#: Positional reward functions r_P by name (a view of :data:`REWARDS`).
POSITIONAL = RegistryView("POSITIONAL", "function", "positional")
#: Directional reward functions r_D by name (a view of :data:`REWARDS`).
DIRECTIONAL = RegistryView("DIRECTIONAL", "function", "directional")
#: The image-head layout of every registered reward, by name (one of
#: :data:`~temporal_torchrl.rewards.registry.IMAGE_LAYOUTS`).
IMAGE_INPUTS = RegistryView("IMAGE_INPUTS", "image_input")
#: The finetuning objective of every registered reward, by name (see
#: :data:`~temporal_torchrl.rewards.registry.OBJECTIVES_BY_KIND`).
OBJECTIVES = RegistryView("OBJECTIVES", "objective")


def register_reward(name: str, function: RewardFunction, *, kind: str,
                    image_input: str | None = "embedding", objective: str | None = None,
                    overwrite: bool = False) -> None:
    """Add a reward function under ``name`` so :class:`TemporalReward` can use it.

    The reward goes into :data:`REWARDS` (and so into the :data:`POSITIONAL` or
    :data:`DIRECTIONAL` view, by ``kind``), with ``image_input``, so
    :func:`~temporal_torchrl.rewards.heads.heads_input_dims` and :class:`TemporalReward` build
    heads of the right sizes, and ``objective``, so the training recipe (and
    :func:`~temporal_torchrl.objectives.finetuning_losses`) trains the heads with the right loss.
    A name is unique across both kinds.

    The function must have the signature of the built-ins::

        fn(heads, s, *, g, b, s0=None, s_prev=None, alpha=ALPHA, position=None,
           projection=PROJECTION, window=None, **unused) -> Tensor

    (:data:`~temporal_torchrl.defaults.ALPHA`,
    :data:`~temporal_torchrl.defaults.PROJECTION`: callers always pass both.)

    - ``heads``: the :class:`~temporal_torchrl.rewards.RewardHeads` (``heads.image``,
      ``heads.text``), or None when ``image_input=None``.
    - ``s``: image embeddings ``[..., D]``; ``s0`` the episode's first embedding, ``s_prev``
      s_{t-k} (the direction is ``s - s_prev``), ``position`` the position at which a directional
      reward scores the direction (None means ``s``); each ``[..., D]`` or None.
    - ``g``, ``b``: goal and baseline text embeddings ``[D]``.
    - ``alpha``, ``projection``: goal-baseline regularisation strength and form (see
      :func:`~temporal_torchrl.rewards.goal_baseline_regularise`).
    - ``window``: the last K embeddings s_{t-K+1} .. s_t ``[..., K, D]`` (oldest first, padded
      with s_0 at the episode start), given to rewards registered with
      ``image_input="window"``, None for the others. A window reward also gets None when the
      straight path from ``s_prev`` to ``s`` is scored (the directional loss's path towards the
      goal, ``TemporalReward.directional_reward(..., straight_path=True)``): it reads that path
      as ``straight_window(s_prev, s, K)``, or scores it without building it, as d_sequence
      does.
    - ``**unused``: callers pass every keyword above; a reward ignores those it does not need.
    - Returns the reward, shape ``s.shape[:-1]`` (differentiable in the heads' parameters for
      the finetuning losses).

    Args:
        name: the variant name (a non-empty string, not ``"none"``, which configs read as None).
        function: the reward function.
        kind: ``"positional"`` or ``"directional"``.
        image_input: what the image head reads: ``"embedding"`` (D inputs, like furl, p1-p4, d1,
            d2), ``"concatenated"`` (2·D inputs: a position part and a direction part, like
            d3-d5), ``"window"`` (a sequence encoder over K - 1 tokens of 2·D, like d_sequence:
            the reward then receives ``window``) or None (zero-shot, no heads, like liv). The
            text head always reads D inputs.
        objective: the loss that finetunes the heads: ``"ranking"`` (positional rewards, the
            default for them), ``"directional"`` (the thesis's directional loss, the default
            for directional rewards) or ``"certainty"`` (directional rewards trained towards a
            certainty target, like d_certainty). Ignored for zero-shot rewards.
        overwrite: replace a reward already registered under ``name`` (of either kind).

    Raises:
        ValueError: for a bad ``name``, ``function``, ``kind``, ``image_input`` or
            ``objective``, or a ``name`` already registered without ``overwrite=True``.

    Example:
        >>> import torch
        >>> from temporal_torchrl.rewards import TemporalReward, cosine_similarity
        >>> def toy(heads, s, *, g, s0=None, **unused):
        ...     # How much closer than the first frame is the current frame to the goal?
        ...     image = heads.image(s) - heads.image(s0)
        ...     return cosine_similarity(image, heads.text(g))
        >>> register_reward("toy", toy, kind="positional")
        >>> D = 8
        >>> reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="toy",
        ...                         directional=None)
        >>> heads = reward.positional_heads
        >>> heads.image_dim, heads.text_dim
        (8, 8)
        >>> s, s0 = torch.randn(3, D), torch.randn(3, D)
        >>> reward(s, s0, s0, torch.zeros(3, 1, dtype=torch.bool))["reward"].shape
        torch.Size([3, 1])
        >>> unregister_reward("toy")
    """
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"register_reward: name={name!r}; expected a non-empty string such as "
                         "'p5'.")
    if name.strip().lower() == "none":
        raise ValueError(f"register_reward: name={name!r} is reserved (configs read 'none' as "
                         "no reward); choose another name.")
    if kind not in KINDS:
        raise ValueError(f"register_reward({name!r}): kind={kind!r}; expected 'positional' "
                         "(a value of the current position) or 'directional' (a value of the "
                         "direction s - s_prev).")
    if image_input not in IMAGE_LAYOUTS:
        raise ValueError(
            f"register_reward({name!r}): image_input={image_input!r}; expected 'embedding' "
            "(the image head reads D inputs), 'concatenated' (2*D inputs: position part and "
            "direction part), 'window' (a sequence encoder over the last K embeddings) or None "
            "(zero-shot, no heads).")
    if image_input == "window" and kind != "directional":
        raise ValueError(f"register_reward({name!r}): image_input='window' is for directional "
                         "rewards (the window's steps are its directions); got kind="
                         f"{kind!r}.")
    objective = OBJECTIVES_BY_KIND[kind][0] if objective is None else objective
    if objective not in OBJECTIVES_BY_KIND[kind]:
        raise ValueError(f"register_reward({name!r}): objective={objective!r}; a {kind} "
                         f"reward is trained with one of {', '.join(OBJECTIVES_BY_KIND[kind])}.")
    if objective == "certainty" and image_input not in ("embedding", "concatenated"):
        raise ValueError(f"register_reward({name!r}): objective='certainty' needs a reward of "
                         "one direction s - s_prev (image_input 'embedding' or "
                         f"'concatenated'); got image_input={image_input!r}.")
    if not callable(function):
        raise ValueError(f"register_reward({name!r}): function={function!r} is not callable; "
                         f"expected a function {_SIGNATURE}.")
    _check_signature(name, function)
    if name in REWARDS and not overwrite:
        raise ValueError(f"register_reward: a {REWARDS[name].kind} reward {name!r} is already "
                         "registered; choose another name or pass overwrite=True to replace "
                         "it.")
    # An overwritten name moves to the end, as a new registration would stand.
    REWARDS.pop(name, None)
    REWARDS[name] = RegisteredReward(function, kind, image_input, objective)


def unregister_reward(name: str) -> None:
    """Remove the reward registered under ``name`` (the inverse of :func:`register_reward`).

    Raises:
        ValueError: if no reward of that name is registered.
    """
    if name not in REWARDS:
        raise ValueError(f"unregister_reward: no reward {name!r} is registered; registered: "
                         f"{', '.join(REWARDS)}.")
    del REWARDS[name]


def registered(name: str) -> RegisteredReward:
    """The :class:`RegisteredReward` of ``name``.

    Raises:
        ValueError: for a name no reward is registered under.
    """
    if name not in REWARDS:
        raise ValueError(f"Unknown reward variant {name!r}; expected one of "
                         f"{', '.join(REWARDS)}, or register it with register_reward().")
    return REWARDS[name]


def single_part(name: str) -> dict[str, str | None]:
    """:class:`~temporal_torchrl.rewards.TemporalReward`'s ``positional`` and ``directional``
    arguments with the reward registered as ``name`` as the only part, in the slot of its kind.

    >>> single_part("d3")
    {'positional': None, 'directional': 'd3'}

    Raises:
        ValueError: for an unknown name.
    """
    return {"positional": None, "directional": None, registered(name).kind: name}


def objective_of(name: str) -> str:
    """The finetuning objective (see :data:`OBJECTIVES_BY_KIND`) of the reward registered as
    ``name``.

    Raises:
        ValueError: for an unknown name.
    """
    return registered(name).objective


def _check_signature(name: str, function: RewardFunction) -> None:
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):  # Some builtins and extension functions have none.
        return
    try:
        signature.bind(None, None, **_CALL_KEYWORDS)
    except TypeError as error:
        raise ValueError(
            f"register_reward({name!r}): {getattr(function, '__name__', function)!r} cannot be "
            f"called the way rewards are ({error}); expected {_SIGNATURE} (**unused takes the "
            "keywords a reward does not need).") from None
