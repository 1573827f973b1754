"""The reward registry: one dict, :data:`REWARDS`, of every registered reward.

Every reward, built-in or a researcher's own, is added with :func:`register_reward`, which records
under its name a :class:`RegisteredReward`: the function, its kind (positional or directional),
what its image head reads, the finetuning objective that trains its heads (a built-in loss, or
one the reward brings) and its options (hyperparameters with their defaults, set from a config's
``reward.options``): those it declares, and those its layout or objective gives it
(:data:`WINDOW_OPTIONS`, :data:`CERTAINTY_OPTIONS`), so d_sequence's window and d_certainty's
certainty estimate are set the way a reward of one's own is. A new reward with a new
hyperparameter is then one file.
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
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from torch import Tensor

from temporal_torchrl.defaults import (
    ALPHA,
    CERTAINTY_BANDWIDTH,
    CERTAINTY_PRIOR,
    PROJECTION,
    WINDOW_LENGTH,
)

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


#: The types an option's default may have (what a config's ``reward.options.<key>`` can hold).
OPTION_TYPES = (bool, int, float, str, type(None))
#: The option every reward registered with ``image_input="window"`` has (d_sequence's, a window
#: reward of one's own alike): the window length K, the number of embeddings s_(t-K+1) .. s_t it
#: reads (``window_length`` everywhere in Python: the option's value, not the window). It sizes
#: the heads' sequence encoder and the windows the history transform and the replay buffer
#: build; the function is not passed K, it receives the window itself as ``window``.
WINDOW_OPTIONS = MappingProxyType({"window": WINDOW_LENGTH})
#: The options every reward registered with ``objective="certainty"`` has (d_certainty's), read
#: by its loss, and those ``TemporalReward(certainty_scaling=True)`` adds to the reward it
#: scales: beta and c of the certainty estimate
#: (:func:`~temporal_torchrl.rewards.certainty.direction_certainty`).
CERTAINTY_OPTIONS = MappingProxyType({"certainty_bandwidth": CERTAINTY_BANDWIDTH,
                                      "certainty_prior": CERTAINTY_PRIOR})
# What the options above take beyond their default's type: a test and its words. A reward's own
# options take any value of their default's type.
_OPTION_RANGES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "window": (lambda value: value >= 2, "an integer >= 2 (K, the embeddings s_(t-K+1) .. s_t "
               "a window reward reads)"),
    "certainty_bandwidth": (lambda value: value > 0, "a number > 0 (beta, the certainty "
                            "kernel's width in median distances)"),
    "certainty_prior": (lambda value: value > 0, "a number > 0 (c, the certainty's "
                        "pseudo-count)"),
}


@dataclass(frozen=True)
class RegisteredReward:
    """One entry of :data:`REWARDS` (see :func:`register_reward` for each field's values).

    Attributes:
        function: the reward function.
        kind: ``"positional"`` or ``"directional"`` (:data:`KINDS`).
        image_input: what the image head reads (:data:`IMAGE_LAYOUTS`).
        objective: the finetuning objective of its heads: one of :data:`OBJECTIVES_BY_KIND`, or
            the name of the reward's own ``loss``.
        options: the reward's options by name, each with its default (read-only): those it
            declared and those of its layout or objective (:data:`WINDOW_OPTIONS`,
            :data:`CERTAINTY_OPTIONS`).
        loss: the reward's own finetuning loss (a
            :class:`~temporal_torchrl.objectives.FinetuningLoss` subclass), or None: the
            built-in loss of ``objective``.
    """

    function: RewardFunction
    kind: str
    image_input: str | None
    objective: str
    options: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    loss: type | None = None

    def keyword_options(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """The options the function is called with, by name: each one's value in ``values``,
        else its default. Not ``window`` (:data:`WINDOW_OPTIONS`): the function receives the
        window of K embeddings itself under that keyword."""
        return {key: values.get(key, default) for key, default in self.options.items()
                if key not in WINDOW_OPTIONS}


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
                    options: Mapping[str, Any] | None = None, loss: type | None = None,
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
    - the reward's ``options``, each by its name: the value a config's
      ``reward.options.<name>`` (``TemporalReward(options=...)``) sets, else its default. Besides
      those it declares, a reward registered with ``objective="certainty"`` has
      :data:`CERTAINTY_OPTIONS`, and one with ``image_input="window"`` has ``window``
      (:data:`WINDOW_OPTIONS`: K, which sizes its window; not passed as a keyword).
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
            certainty target, like d_certainty). Ignored for zero-shot rewards. With ``loss``,
            any name for it (default: the loss class's name).
        options: the reward's own hyperparameters, ``{name: default}``; a default is a bool,
            an int, a float, a string or None. The function receives each as a keyword; a
            config sets one with ``+reward.options.<name>=<value>`` (of the default's type; an
            int where the default is a float), and the reward's loss reads them as
            ``reward.options[name]``. A name must not be one of the keywords above, nor one
            of :data:`CERTAINTY_OPTIONS`, which the ``"certainty"`` objective gives.
        loss: the reward's own finetuning loss, a
            :class:`~temporal_torchrl.objectives.FinetuningLoss` subclass that trains this
            part's heads, constructed as ``loss(reward, goal_image_embedding, stage=stage,
            **settings)`` with those of the finetuning settings (``delta``, ``l2_margin``,
            ``same_position``) its ``__init__`` takes
            (:meth:`~temporal_torchrl.objectives.FinetuningLoss.from_settings`). None: the
            built-in loss of ``objective``.
        overwrite: replace a reward already registered under ``name`` (of either kind).

    Raises:
        ValueError: for a bad ``name``, ``function``, ``kind``, ``image_input``,
            ``objective``, ``options`` or ``loss``, or a ``name`` already registered without
            ``overwrite=True``.

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
    if loss is not None:
        if image_input is None:
            raise ValueError(f"register_reward({name!r}): loss={loss!r} for a zero-shot reward "
                             "(image_input=None), which has no heads to finetune.")
        if not callable(getattr(loss, "from_settings", None)):
            raise ValueError(f"register_reward({name!r}): loss={loss!r}; expected a subclass of "
                             "temporal_torchrl.objectives.FinetuningLoss.")
        objective = loss.__name__ if objective is None else objective
        if not isinstance(objective, str) or not objective:
            raise ValueError(f"register_reward({name!r}): objective={objective!r}; expected "
                             "a name for the reward's own loss.")
    else:
        objective = OBJECTIVES_BY_KIND[kind][0] if objective is None else objective
        if objective not in OBJECTIVES_BY_KIND[kind]:
            raise ValueError(f"register_reward({name!r}): objective={objective!r}; a {kind} "
                             f"reward is trained with one of "
                             f"{', '.join(OBJECTIVES_BY_KIND[kind])}, or pass its own loss=.")
    options = {**_checked_options(name, options),
               **(WINDOW_OPTIONS if image_input == "window" else {}),
               **(CERTAINTY_OPTIONS if objective == "certainty" else {})}
    if objective == "certainty" and image_input not in ("embedding", "concatenated"):
        raise ValueError(f"register_reward({name!r}): objective='certainty' needs a reward of "
                         "one direction s - s_prev (image_input 'embedding' or "
                         f"'concatenated'); got image_input={image_input!r}.")
    if not callable(function):
        raise ValueError(f"register_reward({name!r}): function={function!r} is not callable; "
                         f"expected a function {_SIGNATURE}.")
    _check_signature(name, function, options)
    if name in REWARDS and not overwrite:
        raise ValueError(f"register_reward: a {REWARDS[name].kind} reward {name!r} is already "
                         "registered; choose another name or pass overwrite=True to replace "
                         "it.")
    # An overwritten name moves to the end, as a new registration would stand.
    REWARDS.pop(name, None)
    REWARDS[name] = RegisteredReward(function, kind, image_input, objective,
                                     MappingProxyType(options), loss)


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


def declared_options(parts: Sequence[str], certainty_scaling: bool = False
                     ) -> dict[str, tuple[str, Any]]:
    """Every option a reward of these ``parts`` (registered names) has, ``{key: (whose,
    default)}``: each part's, and with ``certainty_scaling`` :data:`CERTAINTY_OPTIONS`, which
    the scaling's certainty estimate reads (``whose``: ``"certainty_scaling"``). The one list a
    config's ``reward.options`` and ``TemporalReward(options=...)`` are checked against."""
    declared = {key: (name, default) for name in parts
                for key, default in registered(name).options.items()}
    if certainty_scaling:
        declared = {**{key: ("certainty_scaling", default)
                       for key, default in CERTAINTY_OPTIONS.items()}, **declared}
    return declared


def option_expected(name: str, key: str, default: Any) -> str:
    """What the option ``key`` of the reward ``name`` takes, in words: its range for the
    options of :data:`WINDOW_OPTIONS` and :data:`CERTAINTY_OPTIONS`, else a value of the type of
    its ``default`` (not None: an option of default None takes any value)."""
    if key in _OPTION_RANGES:
        return _OPTION_RANGES[key][1]
    return f"a {type(default).__name__} like {name}'s default {default!r}"


def option_value(name: str, key: str, value: Any, default: Any) -> Any:
    """``value`` for the option ``key`` of the reward ``name``, checked against its
    ``default``'s type (an int is taken where the default is a float, as a float) and, for the
    options of :data:`WINDOW_OPTIONS` and :data:`CERTAINTY_OPTIONS`, their range.

    Raises:
        ValueError: for a value of another type or out of range, saying what is expected.
    """
    if default is None:  # any config value
        return value
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if isinstance(default, float) and number:
        value = float(value)
    admitted = type(value) is type(default) and (
        key not in _OPTION_RANGES or _OPTION_RANGES[key][0](value))
    if not admitted:
        raise ValueError(f"option {key}={value!r} of reward {name!r}; expected "
                         f"{option_expected(name, key, default)}.")
    return value


def _checked_options(name: str, options: Mapping[str, Any] | None) -> Mapping[str, Any]:
    if options is None:
        return MappingProxyType({})
    if not isinstance(options, Mapping):
        raise ValueError(f"register_reward({name!r}): options={options!r}; expected a dict of "
                         "each option's default, such as {'beta': 2.0}.")
    for key, default in options.items():
        if not isinstance(key, str) or not key.isidentifier():
            raise ValueError(f"register_reward({name!r}): option name {key!r}; expected a "
                             "Python identifier (the function receives it as a keyword).")
        if key in _CALL_KEYWORDS:
            raise ValueError(f"register_reward({name!r}): option {key!r} is one of the keywords "
                             f"every reward is called with ({', '.join(_CALL_KEYWORDS)}); "
                             "choose another name.")
        if key in CERTAINTY_OPTIONS:
            raise ValueError(f"register_reward({name!r}): option {key!r} is the certainty "
                             "estimate's, which objective='certainty' and certainty_scaling "
                             "give a reward; choose another name.")
        if not isinstance(default, OPTION_TYPES):
            raise ValueError(f"register_reward({name!r}): option {key}={default!r}; a default "
                             "is a bool, an int, a float, a string or None (a config value).")
    return MappingProxyType(dict(options))


def _check_signature(name: str, function: RewardFunction,
                     options: Mapping[str, Any]) -> None:
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):  # Some builtins and extension functions have none.
        return
    keywords = {key: value for key, value in options.items() if key not in WINDOW_OPTIONS}
    try:
        signature.bind(None, None, **_CALL_KEYWORDS, **keywords)
    except TypeError as error:
        raise ValueError(
            f"register_reward({name!r}): {getattr(function, '__name__', function)!r} cannot be "
            f"called the way rewards are ({error}); expected {_SIGNATURE}, its options as keywords "
            "too (**unused takes the keywords a reward does not need).") from None
