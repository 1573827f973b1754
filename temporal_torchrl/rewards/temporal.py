"""The combined temporal reward r_t = r^task_t + rho (r_P(s_t) + lambda r_D(s_t)) (thesis 4.1)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import torch
from torch import Tensor, nn

from temporal_torchrl import defaults
from temporal_torchrl.rewards.certainty import CertaintyMemory
from temporal_torchrl.rewards.heads import RewardHeads, heads_input_dims
from temporal_torchrl.rewards.registry import (
    DIRECTIONAL,
    POSITIONAL,
    REWARDS,
    declared_options,
    option_value,
    registered,
)

REWARD_KEYS = ("task_reward", "positional_reward", "directional_reward", "vlm_reward", "reward")


def check_window_length(window_length: int | None, *, optional: bool = False) -> None:
    """Raise unless ``window_length`` is an integer K >= 2 (or None when ``optional``): the
    window s_(t-K+1) .. s_t of K embeddings, shared by the reward, the history transform and
    the replay buffer."""
    if optional and window_length is None:
        return
    if isinstance(window_length, bool) or not isinstance(window_length, int) \
            or window_length < 2:
        expected = "None or an integer >= 2" if optional else "an integer >= 2"
        raise ValueError(f"window_length={window_length!r}; expected {expected} (the K "
                         "embeddings s_(t-K+1) .. s_t).")


def renamed_k(k: int | None, history: int | None, where: str) -> int | None:
    """``k`` from a public signature that took it as ``history=`` before (deprecated, read for one
    more release): the history offset has one name, ``k`` (``reward.k``), across config,
    constructors and docs. None when neither is given.

    Raises:
        ValueError: both given, with different values; ``where`` names the caller.
    """
    if history is None:
        return k
    if k is not None and k != history:
        raise ValueError(f"{where}: k={k!r} and history={history!r} differ; history= is the "
                         "deprecated name of k=: pass k= alone.")
    warnings.warn(f"{where}: history= is deprecated and will be removed in the next release; "
                  "pass k= (the offset of s_(t-k), reward.k).", FutureWarning, stacklevel=3)
    return history


def resolve_k(k: int | None, reward: TemporalReward | None, where: str) -> int:
    """k for a part that builds histories beside ``reward`` (the env's history transform, the
    replay buffer): the reward's own ``k`` when there is a reward, so k has one route and the
    s_(t-k) the env writes, the replay relabels with and the losses train on is the same one;
    ``k`` (default :data:`~temporal_torchrl.defaults.K`) without a reward.

    Raises:
        ValueError: ``k`` given and not the reward's ``k``; ``where`` names the caller.
    """
    if reward is None:
        return defaults.K if k is None else k
    if k is not None and k != reward.k:
        raise ValueError(
            f"{where}: k={k!r} but reward.k={reward.k}: s_(t-{k}) here against the "
            f"s_(t-{reward.k}) of the reward's history transform. Leave k out (it is taken from "
            f"the reward) or build the reward with k={k}.")
    return reward.k


def resolve_window(window_length: int | None, reward: TemporalReward | None,
                   where: str) -> int | None:
    """The window K a part that builds histories beside ``reward`` carries: the reward's own
    ``window_length`` when there is a reward (None: it reads no window), as :func:`resolve_k`
    does for k; ``window_length`` without a reward.

    Raises:
        ValueError: ``window_length`` given and not the reward's; ``where`` names the caller.
    """
    if reward is None or window_length is None:
        return window_length if reward is None else reward.window_length
    if window_length != reward.window_length:
        raise ValueError(
            f"{where}: window_length={window_length!r} but the reward's window_length is "
            f"{reward.window_length!r}: windows of {window_length} embeddings here against the "
            f"reward's. Leave window_length out (it is taken from the reward) or build the "
            f"reward with window={window_length}.")
    return window_length


class TemporalReward(nn.Module):
    """Positional and directional VLM rewards added to the sparse task reward (thesis 4.1):

    r_t = r^task_t + rho (r^VLM_P(s_t) + lambda r^VLM_D(s_t)),  r^task_t = success_t - 1.

    Every default is the training recipe's (:mod:`~temporal_torchrl.defaults`): the
    thesis's best reward, FuRL + D3 at rho 1, lambda 4 (section 5.3.3).

    Args:
        embedding_dim: size D of the image and text embeddings.
        goal_embedding: g, the goal text embedding ``[D]``.
        baseline_embedding: b, the baseline text embedding ``[D]``.
        positional: a key of :data:`POSITIONAL` (``"furl"``, ``"p1"``-``"p4"``, ``"liv"``, or one
            added with :func:`~temporal_torchrl.rewards.register_reward`) or None.
        directional: a key of :data:`DIRECTIONAL` (``"d1"``-``"d5"``, or one added with
            :func:`~temporal_torchrl.rewards.register_reward`) or None.
        rho: weight of the VLM reward (>= 0; FuRL's own is 0.05, section 5.2).
        lambda_: weight of the directional reward relative to the positional one (>= 0).
        k: history offset of s_{t-k} (>= 1). Carried here as configuration: the history transform
            (:class:`~temporal_torchrl.transforms.EmbeddingHistoryTransform`) produces s_{t-k} and
            should be built with ``k=reward.k``.
        alpha: goal-baseline regularisation strength in [0, 1] (P3, P4, D5).
        projection: ``"origin"`` (the thesis's release) or ``"line"`` (VLM-RMs); see
            :mod:`temporal_torchrl.rewards.positional`.
        certainty_scaling: the multiplicative option of the thesis's section 6.4 proposal
            (beyond the thesis): the directional reward that :meth:`forward` returns is
            ``|t(s_t, Δs_t)|`` r_D, with t from the references of the last finetuning batch
            (:attr:`certainty`). :meth:`directional_reward`, which the finetuning losses call,
            stays unscaled: the heads are trained as they are (the "step function"), the
            factor only shapes the reward the agent sees. Its certainty estimate's beta and c
            are options (:data:`~temporal_torchrl.rewards.registry.CERTAINTY_OPTIONS`).
        options: values of the parts' options, by name (``{"window": 4}``); an option not
            given takes its registered default. A part's options are those
            :func:`~temporal_torchrl.rewards.register_reward` declared and those of its layout
            or objective: ``window``, K, the number of embeddings s_{t-K+1} .. s_t a
            ``"window"`` reward (d_sequence) reads, and ``certainty_bandwidth`` and
            ``certainty_prior``, beta and c of the certainty estimate
            (:func:`~temporal_torchrl.rewards.certainty.direction_certainty`) of the
            ``"certainty"`` objective (d_certainty) and of ``certainty_scaling``. An option
            both parts declare goes to both.

    Attributes:
        positional_heads: the trainable :class:`RewardHeads` f^P, or None when that part is
            absent or zero-shot (registered with ``image_input=None``, like ``"liv"``).
        directional_heads: the trainable :class:`RewardHeads` f^D, or None likewise.
        window_length: K (``options["window"]``) when a part reads the window (registered
            with ``image_input="window"``), else None: the history transform and the replay
            buffer need no window. Like ``k``, configuration for them: they produce the window.
        certainty: the :class:`~temporal_torchrl.rewards.certainty.CertaintyMemory` of
            ``certainty_scaling`` (None without it).
        options: every option of the parts (and of ``certainty_scaling``), by name: the value
            given, else the registered default (empty for the rewards of the thesis, which have
            none). A part's loss reads its hyperparameters here.

    Example:
        >>> import torch
        >>> D = 8
        >>> reward = TemporalReward(D, torch.randn(D), torch.randn(D), positional="furl",
        ...                         directional="d3", rho=1.0, lambda_=4.0)
        >>> s = torch.randn(3, D)
        >>> out = reward(s, s, s, torch.tensor([[False], [True], [False]]))
        >>> out["reward"].shape, out["task_reward"].squeeze(-1).tolist()
        (torch.Size([3, 1]), [-1.0, 0.0, -1.0])
    """

    def __init__(self, embedding_dim: int, goal_embedding: Tensor, baseline_embedding: Tensor,
                 positional: str | None = defaults.POSITIONAL_REWARD,
                 directional: str | None = defaults.DIRECTIONAL_REWARD,
                 rho: float = defaults.RHO, lambda_: float = defaults.LAMBDA,
                 k: int = defaults.K, alpha: float = defaults.ALPHA,
                 projection: str = defaults.PROJECTION,
                 certainty_scaling: bool = False,
                 options: Mapping[str, Any] | None = None, **moved: Any):
        super().__init__()
        options = _with_moved_keywords(options, moved)
        if isinstance(embedding_dim, bool) or not isinstance(embedding_dim, int) \
                or embedding_dim < 1:
            raise ValueError(f"embedding_dim={embedding_dim!r}; expected a positive integer.")
        if positional is not None and positional not in POSITIONAL:
            raise ValueError(f"Unknown positional reward {positional!r}; expected one of "
                             f"{', '.join(POSITIONAL)} or None; add a new one with "
                             "register_reward(name, fn, kind='positional').")
        if directional is not None and directional not in DIRECTIONAL:
            raise ValueError(f"Unknown directional reward {directional!r}; expected one of "
                             f"{', '.join(DIRECTIONAL)} or None; add a new one with "
                             "register_reward(name, fn, kind='directional').")
        if not rho >= 0:
            raise ValueError(f"rho={rho!r}; expected rho >= 0 (the weight of the VLM reward).")
        if not lambda_ >= 0:
            raise ValueError(f"lambda_={lambda_!r}; expected lambda_ >= 0 (the weight of the "
                             "directional reward).")
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ValueError(f"k={k!r}; expected an integer >= 1 (the offset of s_(t-k)).")
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha={alpha!r}; expected 0 <= alpha <= 1 (the goal-baseline "
                             "regularisation strength).")
        if projection not in defaults.PROJECTIONS:
            raise ValueError(f"projection={projection!r}; expected one of "
                             f"{', '.join(defaults.PROJECTIONS)}.")
        if certainty_scaling and directional is None:
            raise ValueError("certainty_scaling=True scales the directional reward; set "
                             "directional too.")
        self.embedding_dim = embedding_dim
        self.positional = positional
        self.directional = directional
        self.rho = float(rho)
        self.lambda_ = float(lambda_)
        self.k = k
        self.alpha = float(alpha)
        self.projection = projection
        self.options = self._options(options or {}, certainty_scaling)
        # Only directional rewards read a window (register_reward enforces it).
        reads_window = directional is not None and REWARDS[directional].image_input == "window"
        self.window_length = self.options["window"] if reads_window else None
        self.certainty = (CertaintyMemory(embedding_dim, self.options["certainty_bandwidth"],
                                          self.options["certainty_prior"])
                          if certainty_scaling else None)
        self.register_buffer("goal_embedding", self._text_embedding(goal_embedding, "goal"))
        self.register_buffer("baseline_embedding",
                             self._text_embedding(baseline_embedding, "baseline"))
        self.positional_heads = self._heads(positional)
        self.directional_heads = self._heads(directional)

    def _options(self, given: Mapping[str, Any], certainty_scaling: bool) -> dict[str, Any]:
        """The parts' options (and ``certainty_scaling``'s), ``given`` values checked against
        the registered defaults."""
        parts = [name for name in (self.positional, self.directional) if name is not None]
        declared = declared_options(parts, certainty_scaling)
        unknown = sorted(set(given) - set(declared))
        if unknown:
            known = ", ".join(declared) or "none"
            raise ValueError(f"options {', '.join(map(repr, unknown))}: not an option of "
                             f"{' or '.join(parts) or 'this reward (no parts)'}; their options: "
                             f"{known} (register_reward(..., options=...) declares them).")
        return {key: option_value(name, key, given[key], default) if key in given else default
                for key, (name, default) in declared.items()}

    def part_options(self, variant: str) -> dict[str, Any]:
        """The keyword arguments of ``variant``'s options in a call of its function: this
        reward's values of them (``options``), else their registered defaults (not
        ``window``: see :meth:`~temporal_torchrl.rewards.RegisteredReward.keyword_options`)."""
        return REWARDS[variant].keyword_options(self.options)

    def _heads(self, variant: str | None) -> RewardHeads | None:
        """Heads sized by the variant's registered image input; None if absent or zero-shot."""
        layout = None if variant is None else registered(variant).image_input
        if layout is None:
            return None
        sequence_length = self.window_length - 1 if layout == "window" else None
        return RewardHeads(*heads_input_dims(variant, self.embedding_dim),
                           sequence_length=sequence_length)

    def _text_embedding(self, value: Tensor, name: str) -> Tensor:
        value = torch.as_tensor(value, dtype=torch.float32)
        if value.shape != (self.embedding_dim,):
            raise ValueError(
                f"{name}_embedding has shape {tuple(value.shape)}; expected ({self.embedding_dim},)"
                f" to match embedding_dim={self.embedding_dim}. Embed the {name} text with the "
                "same encoder as the frames.")
        return value

    def _check_embedding(self, name: str, value: Tensor) -> None:
        if value.shape[-1:] != (self.embedding_dim,):
            raise ValueError(
                f"{name} has size {value.shape[-1] if value.ndim else 'scalar'} in its last "
                f"dimension; the reward heads expect embedding_dim={self.embedding_dim}. Use the "
                "encoder the TemporalReward was built for (its .dim).")

    def _check_window(self, window: Tensor | None) -> None:
        if self.window_length is None:
            return
        if window is None:
            raise ValueError(
                f"Reward {self.directional!r} reads the window of the last "
                f"{self.window_length} embeddings; pass window=... ('embedding_window' from "
                f"EmbeddingHistoryTransform(window_length={self.window_length}) or "
                f"EpisodeReplayBuffer(window_length={self.window_length})).")
        if window.shape[-2:] != (self.window_length, self.embedding_dim):
            raise ValueError(
                f"window has shape {tuple(window.shape)}; expected [..., {self.window_length}, "
                f"{self.embedding_dim}] (window_length={self.window_length}, embedding_dim="
                f"{self.embedding_dim}). Build the history transform and the replay buffer with "
                "window_length=reward.window_length.")

    def positional_reward(self, embedding: Tensor, initial_embedding: Tensor | None = None,
                          previous_embedding: Tensor | None = None,
                          window: Tensor | None = None) -> Tensor:
        """r^VLM_P(s_t) of the configured variant, shape ``embedding.shape[:-1]``.

        The env transform, the replay relabelling and the finetuning losses all call this (and
        :meth:`directional_reward`), so a reward function sees the same ``s0``, ``s_prev`` and
        ``window`` for the same state everywhere.
        """
        self._check_embedding("embedding", embedding)
        if self.positional is None:
            raise ValueError("This TemporalReward has no positional part (positional=None).")
        return REWARDS[self.positional].function(
            self.positional_heads, embedding, s0=initial_embedding, s_prev=previous_embedding,
            g=self.goal_embedding, b=self.baseline_embedding, alpha=self.alpha, position=None,
            projection=self.projection, window=window, **self.part_options(self.positional))

    def directional_reward(self, embedding: Tensor, previous_embedding: Tensor,
                           initial_embedding: Tensor | None = None,
                           position: Tensor | None = None, variant: str | None = None,
                           window: Tensor | None = None, straight_path: bool = False) -> Tensor:
        """r^VLM_D of the direction ``embedding - previous_embedding`` at ``position``
        (default ``embedding``), shape ``embedding.shape[:-1]``; a ``"window"`` reward
        (d_sequence) reads the path ``window`` ``[..., K, D]`` instead (required for it).

        ``straight_path=True`` scores the straight path from ``previous_embedding`` to
        ``embedding`` instead of a window: for a window reward the path
        :func:`~temporal_torchrl.rewards.straight_window` would build, which its function
        receives as ``window=None`` (the directional loss's direction towards the goal); other
        rewards score one direction, which is that path already.

        ``variant`` scores with another registered directional function on this reward's
        directional heads (the release's contrast terms of the directional loss); default the
        configured one. Never scaled by the certainty (see ``certainty_scaling``).
        """
        self._check_embedding("embedding", embedding)
        self._check_embedding("previous_embedding", previous_embedding)
        if self.directional is None:
            raise ValueError("This TemporalReward has no directional part (directional=None).")
        if straight_path and window is not None:
            raise ValueError("straight_path=True scores the straight path from "
                             "previous_embedding to embedding; pass window=None with it.")
        if not straight_path:
            self._check_window(window)
        variant = variant or self.directional
        return REWARDS[variant].function(
            self.directional_heads, embedding, s0=initial_embedding, s_prev=previous_embedding,
            g=self.goal_embedding, b=self.baseline_embedding, alpha=self.alpha,
            position=position, projection=self.projection, window=window,
            **self.part_options(variant))

    def forward(self, embedding: Tensor, initial_embedding: Tensor, previous_embedding: Tensor,
                success: Tensor, window: Tensor | None = None) -> dict[str, Tensor]:
        """All reward parts for embeddings ``[..., D]`` and ``success`` ``[..., 1]`` (and the
        ``window`` ``[..., K, D]`` when a part reads it).

        Returns a dict with ``"task_reward"`` (success - 1), ``"positional_reward"`` (r_P),
        ``"directional_reward"`` (r_D, times ``|t(s_t, Δs_t)|`` with ``certainty_scaling``),
        ``"vlm_reward"`` (r_P + lambda r_D) and ``"reward"`` (r_task + rho vlm), each float32
        ``[..., 1]``; an absent part is 0.
        """
        self._check_embedding("initial_embedding", initial_embedding)
        task = success.to(torch.float32) - 1.0
        zeros = torch.zeros_like(task)
        positional = (self.positional_reward(embedding, initial_embedding,
                                             previous_embedding, window).unsqueeze(-1)
                      if self.positional is not None else zeros)
        directional = zeros
        if self.directional is not None:
            directional = self.directional_reward(embedding, previous_embedding,
                                                  initial_embedding, window=window)
            if self.certainty is not None:
                directional = directional * self.certainty(
                    embedding, embedding - previous_embedding).abs()
            directional = directional.unsqueeze(-1)
        vlm = positional + self.lambda_ * directional
        return {"task_reward": task, "positional_reward": positional,
                "directional_reward": directional, "vlm_reward": vlm,
                "reward": task + self.rho * vlm}

    def extra_repr(self) -> str:
        scaling = "" if self.certainty is None else ", certainty_scaling=True"
        options = f", options={self.options!r}" if self.options else ""
        return (f"embedding_dim={self.embedding_dim}, positional={self.positional!r}, "
                f"directional={self.directional!r}, rho={self.rho}, lambda_={self.lambda_}, "
                f"k={self.k}, alpha={self.alpha}, projection={self.projection!r}{scaling}"
                f"{options}")


#: Keywords TemporalReward took before its rewards' hyperparameters became registry options, and
#: the option each became (kept for one release, with a FutureWarning).
MOVED_KEYWORDS = {"window_length": "window", "certainty_bandwidth": "certainty_bandwidth",
                  "certainty_prior": "certainty_prior"}


def _with_moved_keywords(options: Mapping[str, Any] | None,
                         moved: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """``options`` with the old keywords in ``moved`` (:data:`MOVED_KEYWORDS`) moved in, each
    with a FutureWarning naming its new spelling; any other keyword is a TypeError."""
    unknown = set(moved) - set(MOVED_KEYWORDS)
    if unknown:
        raise TypeError(f"TemporalReward() got unexpected keyword(s) {', '.join(sorted(unknown))}"
                        f"; a reward's own hyperparameters go in options={{name: value}}.")
    if not moved:
        return options
    merged = dict(options or {})
    for keyword, value in moved.items():
        option = MOVED_KEYWORDS[keyword]
        warnings.warn(f"TemporalReward({keyword}=...) is deprecated and will be removed in the "
                      f"next release; pass options={{{option!r}: {value!r}}}.", FutureWarning,
                      stacklevel=3)
        if option in merged and merged[option] != value:
            raise ValueError(f"TemporalReward: {keyword}={value!r} and options[{option!r}]="
                             f"{merged[option]!r} disagree; pass options[{option!r}] only.")
        merged[option] = value
    return merged
