"""The offline reward-quality dataset: embedded successful and failed episodes of one task.

Three kinds of episodes of one task and seed (one layout), rendered and embedded exactly as a
training run renders and embeds them (:func:`~temporal_torchrl.envs.make_env` with the run's
render settings, :func:`~temporal_torchrl.data.embed_episode`):

- ``"expert"``: the scripted expert with a small action noise (0.1, as the stage-2 preloaded
  positives), cut a few steps after its first success. Every kept one succeeds: the positives.
- ``"random"``: uniform random actions, as in a training run's warm-up; kept only when they
  never succeed.
- ``"failed_expert"``: the scripted expert with a large action noise, kept only when it never
  succeeds: failures that still move towards the goal for a while, harder negatives than random
  actions. Metaworld's experts are closed-loop and recover from a lot of noise (window-open and
  button-press-topdown still succeed at noise 4 within 500 steps; window-close needs about 8),
  so the noise starts at ``failure_noise`` and is doubled whenever three in four of the
  episodes tried at the current noise (at least four) succeeded; each kept episode records its
  noise. At noise 8 and more the expert's action is mostly noise: such failures are close to
  random ones.

Episodes keep the ``env.rollout()`` layout ``[T]`` (pixels dropped), so they go into an
:class:`~temporal_torchrl.data.EpisodeReplayBuffer` as training episodes do. Collected datasets
are cached on disk, keyed by everything that decides their content (:func:`load_or_collect`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict

from temporal_torchrl import defaults
from temporal_torchrl.data import embed_episode
from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs import (
    TASKS,
    collect_expert_episodes,
    collect_successful_experts,
    make_env,
)
from temporal_torchrl.fields import check_fields, field_of
from temporal_torchrl.params import DatasetParams, EnvParams

#: Episode kinds, positives first.
EPISODE_KINDS = ("expert", "random", "failed_expert")
#: What an episode keeps (the keys a training episode brings to the replay buffer).
EPISODE_KEYS = ("observation", "embedding", "action", "success", ("next", "observation"),
                ("next", "embedding"), ("next", "success"), ("next", "terminated"),
                ("next", "truncated"), ("next", "done"))
#: Version of the cache file layout; files of another version are collected again.
CACHE_FORMAT = 2
#: Offset of the failed experts' noise seeds, far from the successful experts' retry seeds
#: (:func:`~temporal_torchrl.envs.collect_successful_experts`), so the kinds never share a noise
#: stream.
_FAILURE_SEED = 100_000


@dataclass(frozen=True)
class DatasetSpec:
    """Everything that decides a dataset's content (and its cache key), encoder aside: the
    env's settings (:class:`~temporal_torchrl.params.EnvParams`'s but the goal: the episodes
    are on the seed's layout) and the episodes (:class:`~temporal_torchrl.params.DatasetParams`),
    each field's default and range taken from its parameter object.

    Attributes:
        task: Metaworld task short name, e.g. ``"drawer-open"``.
        seed: the layout (as a training run's ``env.seed``) and the seed of every noise stream.
        image_size, camera, fast_render: the render settings of the training run.
        max_episode_steps: length of the random and failed episodes (500 in the protocol);
            experts get at least 500 steps to succeed, as in training.
        expert_episodes, random_episodes, failed_expert_episodes, expert_noise,
            expert_steps_after_success, failure_noise, max_attempts: as in
            :class:`~temporal_torchrl.params.DatasetParams`.

    Example:
        >>> from temporal_torchrl.params import DatasetParams, EnvParams
        >>> spec = DatasetSpec.of(EnvParams("push", seed=2), DatasetParams(expert_episodes=4))
        >>> spec.task, spec.seed, spec.image_size, spec.expert_episodes, spec.random_episodes
        ('push', 2, 64, 4, 6)
    """

    task: str
    seed: int = field_of(EnvParams, "seed")
    image_size: int = field_of(EnvParams, "image_size")
    camera: str = field_of(EnvParams, "camera")
    fast_render: bool = field_of(EnvParams, "fast_render")
    max_episode_steps: int = field_of(EnvParams, "max_episode_steps")
    expert_episodes: int = field_of(DatasetParams, "expert_episodes")
    random_episodes: int = field_of(DatasetParams, "random_episodes")
    failed_expert_episodes: int = field_of(DatasetParams, "failed_expert_episodes")
    expert_noise: float = field_of(DatasetParams, "expert_noise")
    expert_steps_after_success: int | None = field_of(DatasetParams,
                                                      "expert_steps_after_success")
    failure_noise: float = field_of(DatasetParams, "failure_noise")
    max_attempts: int = field_of(DatasetParams, "max_attempts")

    @classmethod
    def of(cls, env: EnvParams, dataset: DatasetParams) -> DatasetSpec:
        """The spec of ``env``'s task, layout and frames and ``dataset``'s episodes (a random
        goal setting is refused: the episodes are scored on the seed's layout)."""
        if env.goal != defaults.FIXED_GOAL:
            raise ValueError(f"DatasetSpec: goal={env.goal!r}; the reward-quality episodes are "
                             f"collected on the seed's layout: use goal={defaults.FIXED_GOAL!r}.")
        env_fields = {name: getattr(env, name) for name in
                      ("task", "seed", "image_size", "camera", "fast_render",
                       "max_episode_steps")}
        dataset_fields = {spec.name: getattr(dataset, spec.name)
                          for spec in dataclasses.fields(DatasetParams)}
        return cls(**env_fields, **dataset_fields)

    @property
    def env(self) -> EnvParams:
        """The env the episodes are collected in (on the seed's layout)."""
        return EnvParams(task=self.task, seed=self.seed, image_size=self.image_size,
                         camera=self.camera, fast_render=self.fast_render,
                         max_episode_steps=self.max_episode_steps)

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"DatasetSpec: task={self.task!r} is not a Metaworld MT50 task; "
                             "expected a short name such as 'drawer-open'.")
        check_fields(self)
        if self.expert_episodes < 2 or max(self.random_episodes,
                                           self.failed_expert_episodes) < 2:
            raise ValueError(
                f"DatasetSpec: {self.expert_episodes} expert, {self.random_episodes} random and "
                f"{self.failed_expert_episodes} failed-expert episodes; expected at least 2 "
                "experts and 2 random or 2 failed-expert episodes: the split holds out episodes "
                "of each kind (split_by_episode), and a kind needs 2 to appear on both sides.")


@dataclass
class RewardDataset:
    """Embedded episodes of one task with their kind (:data:`EPISODE_KINDS`) and action noise.

    Attributes:
        episodes: one TensorDict ``[T]`` per episode, in ``env.rollout()`` layout with
            ``"embedding"`` and ``("next", "embedding")``, no pixels.
        kinds: the kind of each episode.
        noises: the action noise of each episode (``None`` for uniform random actions).
        spec: what was collected.
        collection_seconds: wall time of the collection (rendering and embedding).
    """

    episodes: list[TensorDict]
    kinds: list[str]
    noises: list[float | None]
    spec: DatasetSpec
    collection_seconds: float = 0.0
    source: str = field(default="collected", compare=False)

    def __post_init__(self) -> None:
        if not len(self.episodes) == len(self.kinds) == len(self.noises):
            raise ValueError(f"RewardDataset: {len(self.episodes)} episodes, {len(self.kinds)} "
                             f"kinds and {len(self.noises)} noises; expected one of each per "
                             "episode.")
        unknown = sorted(set(self.kinds) - set(EPISODE_KINDS))
        if unknown:
            raise ValueError(f"RewardDataset: unknown episode kinds {unknown}; expected "
                             f"{', '.join(EPISODE_KINDS)}.")

    def __len__(self) -> int:
        return len(self.episodes)

    @property
    def successful(self) -> list[bool]:
        """Whether each episode reaches success at some step (the experts do, no other does)."""
        return [bool(episode["next", "success"].any()) for episode in self.episodes]

    def subset(self, indices: Sequence[int]) -> RewardDataset:
        """The episodes at ``indices``, in that order."""
        return dataclasses.replace(
            self, episodes=[self.episodes[i] for i in indices],
            kinds=[self.kinds[i] for i in indices], noises=[self.noises[i] for i in indices])

    def describe(self) -> dict[str, dict[str, Any]]:
        """Episodes, steps and action noises per kind, e.g. for a results file."""
        summary: dict[str, dict[str, Any]] = {}
        for kind in EPISODE_KINDS:
            members = [i for i, k in enumerate(self.kinds) if k == kind]
            noises = sorted({self.noises[i] for i in members if self.noises[i] is not None})
            summary[kind] = {"episodes": len(members),
                             "steps": sum(len(self.episodes[i]) for i in members),
                             "noise": noises}
        return summary


def split_by_episode(kinds: Sequence[str], held_out_fraction: float, seed: int = 0
                     ) -> tuple[list[int], list[int]]:
    """Training and held-out episode indices, split per kind: no episode is on both sides.

    Within each kind, ``round(held_out_fraction * n)`` episodes, at least one and at most
    ``n - 1``, are held out, chosen by a permutation seeded with ``seed``; a kind with a single
    episode goes to training. Indices are returned sorted.

    >>> split_by_episode(["expert"] * 4 + ["random"] * 2, 0.25)
    ([1, 2, 3, 5], [0, 4])
    """
    if not 0.0 < held_out_fraction < 1.0:
        raise ValueError(f"held_out_fraction={held_out_fraction!r}; expected a fraction in "
                         "(0, 1), e.g. 0.33 to hold out a third of each kind's episodes.")
    generator = torch.Generator().manual_seed(seed)
    train, held_out = [], []
    for kind in dict.fromkeys(kinds):  # kinds in order of first appearance
        members = [index for index, k in enumerate(kinds) if k == kind]
        order = torch.randperm(len(members), generator=generator).tolist()
        count = min(max(round(held_out_fraction * len(members)), 1), len(members) - 1)
        held_out += [members[i] for i in order[:count]]
        train += [members[i] for i in order[count:]]
    return sorted(train), sorted(held_out)


def _kept(episode: TensorDict) -> TensorDict:
    return episode.select(*EPISODE_KEYS, strict=False)


def _embedded(episodes: list[TensorDict], encoder: Encoder) -> list[TensorDict]:
    return [_kept(embed_episode(episode, encoder)) for episode in episodes]


def _collect_experts(spec: DatasetSpec, encoder: Encoder, render: bool) -> list[TensorDict]:
    try:
        experts = collect_successful_experts(
            spec.env.replace(max_episode_steps=max(spec.max_episode_steps,
                                                   defaults.MAX_EPISODE_STEPS)),
            spec.expert_episodes, noise=spec.expert_noise, render=render,
            steps_after_success=spec.expert_steps_after_success, max_attempts=spec.max_attempts)
    except RuntimeError as error:
        raise RuntimeError(f"{error} In this benchmark's config: dataset.expert_noise and "
                           "dataset.max_attempts.") from error
    return _embedded(experts, encoder)


def _collect_random(spec: DatasetSpec, encoder: Encoder, render: bool) -> list[TensorDict]:
    env = make_env(spec.env, render=render)
    episodes: list[TensorDict] = []
    attempts = spec.max_attempts * spec.random_episodes
    try:
        # The env draws random actions from torch's global generator: seed it here without
        # changing the caller's stream.
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(spec.seed)
            for _ in range(attempts):
                episode = env.rollout(spec.max_episode_steps, break_when_any_done=True)
                if not bool(episode["next", "success"].any()):
                    episodes += _embedded([episode], encoder)
                if len(episodes) == spec.random_episodes:
                    return episodes
    finally:
        env.close()
    raise RuntimeError(f"uniform random actions succeeded in {spec.task} too often: only "
                       f"{len(episodes)} of {attempts} episodes failed, "
                       f"{spec.random_episodes} wanted; shorten env.max_episode_steps.")


def _collect_failed_experts(spec: DatasetSpec, encoder: Encoder, render: bool
                            ) -> tuple[list[TensorDict], list[float]]:
    episodes: list[TensorDict] = []
    noises: list[float] = []
    noise = spec.failure_noise
    tried_at_noise = succeeded_at_noise = 0
    attempts = spec.max_attempts * spec.failed_expert_episodes
    for attempt in range(attempts):
        # One episode per call, so no failure beyond the wanted number is rendered; an episode
        # that succeeds is cut at its success (steps_after_success=0) and costs only its steps.
        episode, = collect_expert_episodes(
            spec.env, num_episodes=1, noise=noise, render=render, steps_after_success=0,
            generator_seed=spec.seed + _FAILURE_SEED + attempt)
        tried_at_noise += 1
        if bool(episode["next", "success"].any()):
            succeeded_at_noise += 1
        else:
            episodes += _embedded([episode], encoder)
            noises.append(noise)
            if len(episodes) == spec.failed_expert_episodes:
                return episodes, noises
        if tried_at_noise >= 4 and 4 * succeeded_at_noise >= 3 * tried_at_noise:
            # Three in four succeed at this noise: too little for this task. Doubling only then
            # keeps the noise as low as failures allow (the closer to the expert, the harder).
            noise *= 2
            tried_at_noise = succeeded_at_noise = 0
    raise RuntimeError(
        f"the noisy expert of {spec.task} failed in only {len(episodes)} of {attempts} episodes, "
        f"{spec.failed_expert_episodes} wanted (noise {spec.failure_noise} doubled up to "
        f"{noise}); raise dataset.failure_noise or dataset.max_attempts, or shorten "
        "env.max_episode_steps.")


def collect_reward_dataset(spec: DatasetSpec, encoder: Encoder) -> RewardDataset:
    """Collect and embed the expert, random and failed-expert episodes of ``spec``.

    Frames are rendered when the encoder reads pixels (with the spec's render settings) and
    embedded by ``encoder``; state encoders read the observations and nothing is rendered.
    """
    render = encoder.input_key == "pixels"
    start = time.perf_counter()
    experts = _collect_experts(spec, encoder, render)
    randoms = _collect_random(spec, encoder, render) if spec.random_episodes else []
    failed, failure_noises = (_collect_failed_experts(spec, encoder, render)
                              if spec.failed_expert_episodes else ([], []))
    return RewardDataset(
        episodes=[*experts, *randoms, *failed],
        kinds=["expert"] * len(experts) + ["random"] * len(randoms)
        + ["failed_expert"] * len(failed),
        noises=[spec.expert_noise] * len(experts) + [None] * len(randoms) + failure_noises,
        spec=spec, collection_seconds=time.perf_counter() - start)


def encoder_fingerprint(encoder: Encoder, description: dict[str, Any] | None = None) -> str:
    """A hash of the encoder's weights, name and size, and of ``description``.

    ``description`` carries what the weights do not show, such as the preprocessing options
    an encoder was loaded with.
    """
    digest = hashlib.sha256(json.dumps([encoder.name, encoder.dim, encoder.input_key,
                                        description or {}], sort_keys=True,
                                       default=str).encode())
    for name, tensor in sorted(encoder.state_dict().items()):
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().contiguous().reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def cache_path(cache_dir: str | Path, spec: DatasetSpec, fingerprint: str) -> Path:
    """Where :func:`load_or_collect` keeps the dataset of ``spec`` embedded by an encoder."""
    key = json.dumps({"format": CACHE_FORMAT, "spec": dataclasses.asdict(spec),
                      "encoder": fingerprint}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return Path(cache_dir) / f"{spec.task}_seed{spec.seed}_{digest}.pt"


def save_dataset(dataset: RewardDataset, path: str | Path, fingerprint: str) -> None:
    """Write ``dataset`` to ``path`` (through a temporary file: a kill leaves no half file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format": CACHE_FORMAT, "spec": dataclasses.asdict(dataset.spec),
               "encoder": fingerprint, "kinds": list(dataset.kinds),
               "noises": list(dataset.noises), "collection_seconds": dataset.collection_seconds,
               "episodes": [episode.to_dict() for episode in dataset.episodes]}
    temporary = path.with_suffix(".tmp")
    torch.save(payload, temporary)
    temporary.replace(path)


def load_dataset(path: str | Path, spec: DatasetSpec, fingerprint: str) -> RewardDataset | None:
    """The dataset cached at ``path`` if it holds ``spec`` embedded by that encoder, else None."""
    path = Path(path)
    if not path.is_file():
        return None
    payload = torch.load(path, weights_only=True)
    if (payload.get("format") != CACHE_FORMAT or payload.get("encoder") != fingerprint
            or payload.get("spec") != dataclasses.asdict(spec)):
        return None
    episodes = [TensorDict(data, [data["action"].shape[0]]) for data in payload["episodes"]]
    return RewardDataset(episodes, list(payload["kinds"]), list(payload["noises"]), spec,
                         float(payload["collection_seconds"]), source=str(path))


def load_or_collect(spec: DatasetSpec, encoder: Encoder, cache_dir: str | Path | None,
                    encoder_description: dict[str, Any] | None = None) -> RewardDataset:
    """The dataset of ``spec`` from ``cache_dir`` when cached there, else collected and cached.

    The cache file name hashes the spec and :func:`encoder_fingerprint` (weights and
    ``encoder_description``), so another task, seed, render setting, dataset size or encoder
    collects a new dataset. ``cache_dir=None`` always collects and caches nothing.
    """
    if cache_dir is None:
        return collect_reward_dataset(spec, encoder)
    fingerprint = encoder_fingerprint(encoder, encoder_description)
    path = cache_path(cache_dir, spec, fingerprint)
    dataset = load_dataset(path, spec, fingerprint)
    if dataset is None:
        dataset = collect_reward_dataset(spec, encoder)
        save_dataset(dataset, path, fingerprint)
        dataset.source = f"collected, cached in {path}"
    return dataset
