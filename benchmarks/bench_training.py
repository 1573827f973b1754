"""Training throughput: the updates against their compute bound, the whole loop, the replay.

Sections (``--sections``, default all), each row next to its reference measured in the same run:

sac     the SAC update alone (batch 256, (256, 256) networks, fused Adam): the recipe's eager
        update (``StackedCriticSACLoss``) against its compute bound, against
        TorchRL's ``SACLoss`` as its docs build it (vmap over the critics, the whole replay
        batch) and against a plain-PyTorch twin-critic update; the recipe's update compiled
        (``compile.enabled``) against it eager, and both against the bound in 5 alternating
        rounds, each with its own GEMM rate.
heads   the reward-head update alone (FuRL's ranking loss and D3's directional loss, stage 2,
        batch 256, D = 1024 and 256) against its compute bound and against the same two losses
        scored one term at a time with one backward per loss (the trainer before the terms
        were joined).
step    the training step as the recipe runs it: one reward-head update, one SAC batch sampled
        and relabelled, one SAC update; stage 2, D = 1024. Eager against the compute bound, and
        compiled (``torch.compile``) against eager in ``--repeats`` fresh builds (min, median,
        max), with the compile time of the first; and compile's ceiling: the eager step with
        the parts it compiles (the head losses' forward and backward, the relabelling's reward,
        the SAC update) cut to their matmuls alone.
loop    the whole default loop (the shipped encoder at 64 px, FuRL + D3, stage 1 with relay, 1
        env, eager), env steps/s in the steady state (the 3rd and 4th episodes, timed at their
        ends: the 1st has no updates), against its bound (its env side, measured without
        updates, plus its updates' FLOPs at the GEMM rate), its ceiling (the env side plus its
        updates' matmuls alone), compiled (``--compile-mode``) against eager in alternating
        fresh processes, and, with ``--baseline-rev REV``, against that git revision's loop,
        run from a worktree by this script in a subprocess.
sequence  d_sequence (K = 8) against D3: the reward-head update (FuRL + the directional loss,
        D = 1024) and the training step in stage 1 and 2, alternating in one process; the whole
        loop (state encoder, D = 1024, 1 env, eager) in ``--rounds`` alternating runs of each
        (default 3).
grid    the whole recipe for the state encoder (D = 1024), the shipped encoder and a
        random-weight LIV at 224 px; ``env.num_envs`` 1, 2 and 4, eager and compiled; against
        the loop of one env, eager, of the same encoder; with CUDA also LIV with 16 envs,
        everything on the GPU, compiled.
reference  the recipe without a VLM reward against a plain TorchRL SAC loop on the same env
        (TensorDictReplayBuffer, same networks and schedule): the recipe's own overhead.
replay  sampling 256 transitions with their histories at 500,000 transitions (D = 1024) against
        TorchRL's SliceSampler(slice_len=2) on the same float16 embeddings; a stage-2 finetuning
        batch; the replay memory against storing s_t and s_{t+1} in float32.

Compute bounds: the FLOPs torch's profiler counts (``with_flops``: the matrix products) divided
by this machine's fp32 GEMM rate (a 2048^3 matmul, measured in the same run). Matmuls alone:
the matrix products one call dispatches, forward and backward, recorded and replayed by
themselves at their shapes and strides; their share of the time bounds what any speed-up
that keeps the same matmul kernels (compile included) can give, and the loop's ceiling is its
env side plus its updates' matmuls alone.
``--threads`` sets torch's threads (default: all cores). ``--quick`` shortens everything.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch
import torch.nn.functional as F
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torch import nn
from torch.profiler import ProfilerActivity, profile
from torch.utils._python_dispatch import TorchDispatchMode
from torchrl.data import LazyTensorStorage, SliceSampler, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp
from torchrl.modules import MLP, ValueOperator

# The tree whose recipe and package are measured: this checkout, or (the --baseline-rev rows)
# a worktree of another revision, which the benchmark runs itself in with this variable set.
# Before the first import of the package (_common imports it too).
TREE = Path(os.environ.get("TEMPORAL_TORCHRL_TREE", Path(__file__).resolve().parents[1]))
RECIPES = TREE / "recipes"
sys.path[:0] = [str(RECIPES), str(TREE)]

import sac_temporal  # noqa: E402
from _common import machine_description, report, seconds_per_call  # noqa: E402

import temporal_torchrl  # noqa: E402
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows  # noqa: E402
from temporal_torchrl.envs import make_env  # noqa: E402
from temporal_torchrl.objectives import ranking_loss  # noqa: E402
from temporal_torchrl.training import factories  # noqa: E402

SECTIONS = ("sac", "heads", "step", "loop", "sequence", "grid", "reference", "replay")
RUN_IDS = itertools.count()  # a fresh output_dir per recipe run
OBSERVATION_DIM, ACTION_DIM = 39, 4  # Metaworld's state and action


def recipe_config(output_dir: Path, *overrides: str):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("config", overrides=[
            f"output_dir={output_dir}", "logger.backend=none", "train.progress=false",
            "train.random_steps=0", "reward.positional=furl", "reward.directional=d3",
            "reward.lambda_=4.0", "reward.rho=1.0", "train.device=cpu", *overrides])


def synthetic_episode(length: int, dim: int, success_from: int | None = None) -> TensorDict:
    embedding, observation = torch.randn(length + 1, dim), torch.randn(length + 1, 39)
    success = torch.zeros(length + 1, 1, dtype=torch.bool)
    if success_from is not None:
        success[success_from:] = True
    return TensorDict({
        "observation": observation[:-1], "embedding": embedding[:-1],
        "action": torch.rand(length, 4) * 2 - 1, "success": success[:-1],
        "next": {"observation": observation[1:], "embedding": embedding[1:],
                 "success": success[1:],
                 "terminated": torch.zeros(length, 1, dtype=torch.bool)}}, [length])


# --------------------------------------------------------------------------- step
def training_setup(tmp: Path, dim: int, *overrides: str, stage: int = 2) -> dict:
    """The recipe's reward, buffer (10 synthetic 500-step episodes, the first successful in
    ``stage`` 2), reward-head trainer and SAC update, built by its factories for the state
    encoder at D."""
    cfg = recipe_config(tmp / f"setup_{next(RUN_IDS)}", "encoder.name=state",
                        f"+encoder.options.dim={dim}", *overrides)
    torch.manual_seed(0)
    reward = factories.make_reward(cfg, factories.make_encoder(cfg))
    env = factories.make_environment(cfg, None, None)
    actor, critics = factories.make_sac_agent(cfg, env)
    env.close()
    loss, optimizer = factories.make_sac_loss(cfg, actor, critics, 4)
    buffer = factories.make_replay_buffer(cfg, 20 * 501, reward)
    buffer.extend(episode_rows(synthetic_episode(500, dim,
                                                 success_from=300 if stage == 2 else None)))
    for _ in range(9):
        buffer.extend(episode_rows(synthetic_episode(500, dim)))
    trainer = factories.make_reward_trainer(cfg, reward, torch.randn(dim), buffer)
    assert trainer.stage == stage
    return {"cfg": cfg, "buffer": buffer, "trainer": trainer, "actor": actor, "loss": loss,
            "update_sac": factories.make_sac_update(cfg, loss, optimizer)}


def training_step(compiled: bool, tmp: Path, mode: str | None = None):
    """The recipe's step (head update, SAC batch + relabel, SAC update) on a stage-2 buffer."""
    setup = training_setup(tmp, 1024, f"compile.enabled={str(compiled).lower()}",
                            f"compile.mode={mode or 'null'}")
    trainer, buffer, update_sac = setup["trainer"], setup["buffer"], setup["update_sac"]

    def step() -> None:
        trainer.update()
        update_sac(buffer.sample())

    return step


def counted_flops(fn) -> float:
    """The FLOPs of one call of ``fn`` (after one warm-up call), as torch's profiler counts."""
    fn()
    with profile(activities=[ProfilerActivity.CPU], with_flops=True) as profiler:
        fn()
    return sum(event.flops for event in profiler.key_averages())


def bound_row(measure: str, seconds: float, flops: float, peak: float) -> dict:
    bound = flops / peak
    return {"measure": measure, "project": 1000 * seconds, "reference": 1000 * bound,
            "reference is": f"compute bound: {flops / 1e9:.2f} GFLOP / {peak / 1e9:.0f} GFLOP/s "
                            "GEMM", "ratio": bound / seconds}


def spread(values: list[float]) -> str:
    """``min / median / max`` of ``values``, as the rows write them."""
    values = sorted(values)
    return (f"min / median / max {values[0]:.2f} / {statistics.median(values):.2f} / "
            f"{values[-1]:.2f}")


def bound_row_by_round(measure: str, seconds: list[float], flops: float,
                       peaks: list[float]) -> dict:
    """:func:`bound_row` for timings taken in rounds, each against the GEMM rate measured in
    its own round (this VM's load moves both): the medians, and the fraction's spread."""
    fractions = [flops / peak / time for peak, time in zip(peaks, seconds, strict=True)]
    peak = statistics.median(peaks)
    return {**bound_row(measure, statistics.median(seconds), flops, peak),
            "reference is": f"compute bound: {flops / 1e9:.2f} GFLOP / {peak / 1e9:.0f} GFLOP/s "
                            f"GEMM, each round's (fraction {spread(fractions)})",
            "ratio": statistics.median(fractions)}


def alternating_seconds(calls: dict[str, Callable[[], object]], rounds: int,
                        min_seconds: float) -> dict[str, list[float]]:
    """Seconds per call of each of ``calls`` in ``rounds`` rounds, the calls taking turns within
    each round, so that the machine's load changes reach them all alike."""
    times = {name: [] for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            times[name].append(seconds_per_call(call, min_seconds=min_seconds, warmup_calls=3))
    return times


class MatmulRecorder(TorchDispatchMode):
    """Records the matrix products dispatched inside it, forward and backward: each one's op,
    its tensor arguments' shapes, strides and dtypes, and its other arguments."""

    MATMULS = (torch.ops.aten.mm, torch.ops.aten.addmm, torch.ops.aten.bmm,
               torch.ops.aten.baddbmm)

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func.overloadpacket in self.MATMULS:
            layout = [(a.shape, a.stride(), a.dtype) if isinstance(a, torch.Tensor) else a
                      for a in args]
            self.calls.append((func, layout, kwargs))
        return func(*args, **kwargs)


def matmuls_alone(fn):
    """A call running only the matrix products that one call of ``fn`` (after a warm-up call)
    dispatches, forward and backward, on random operands of the same shapes, strides and
    dtypes: ``fn`` as if everything but its matmuls took no time."""
    fn()
    recorder = MatmulRecorder()
    with recorder:
        fn()

    def operand(argument):
        if not (isinstance(argument, tuple) and len(argument) == 3
                and isinstance(argument[2], torch.dtype)):
            return argument
        shape, stride, dtype = argument
        storage = 1 + sum((size - 1) * step for size, step in zip(shape, stride, strict=True))
        return torch.randn(storage, dtype=dtype).as_strided(shape, stride)

    calls = [(func, [operand(a) for a in layout], kwargs)
             for func, layout, kwargs in recorder.calls]

    def replay() -> None:
        for func, args, kwargs in calls:
            func(*args, **kwargs)

    return replay


def matmul_row(measure: str, seconds: float, matmul_seconds: float) -> dict:
    """``seconds`` against its matmuls alone: the ratio is the share of its time they take, and
    its inverse the most that any speed-up keeping the same matmul kernels can give."""
    return {"measure": measure, "project": 1000 * seconds, "reference": 1000 * matmul_seconds,
            "reference is": "its matmuls alone (replayed at their shapes)",
            "ratio": matmul_seconds / seconds}


#: The matmul whose rate is the machine's fp32 GEMM rate: 2048^3, and its FLOPs.
GEMM_SIZE = 2048
GEMM_FLOPS = 2 * GEMM_SIZE ** 3


def gemm() -> Callable[[], torch.Tensor]:
    """One call of the reference matmul (``GEMM_FLOPS``), on operands made once."""
    a, b = torch.randn(GEMM_SIZE, GEMM_SIZE), torch.randn(GEMM_SIZE, GEMM_SIZE)
    return lambda: a @ b


def gemm_flops_per_second(min_seconds: float = 2.0) -> float:
    return GEMM_FLOPS / seconds_per_call(gemm(), min_seconds=min_seconds)


# --------------------------------------------------------------------------- sac
class PlainSAC(nn.Module):
    """SAC's update in plain PyTorch, CleanRL's shape: a tanh-Gaussian actor, two critics and
    their targets as separate MLPs, one Adam each for the critics, the actor and the
    temperature; the recipe's sizes, learning rate, gamma, tau and target entropy."""

    def __init__(self, cfg, observation_dim: int = OBSERVATION_DIM,
                 action_dim: int = ACTION_DIM) -> None:
        super().__init__()
        hidden = list(cfg.sac.hidden_sizes)

        def mlp(inputs: int, outputs: int) -> nn.Sequential:
            layers, width = [], inputs
            for size in hidden:
                layers += [nn.Linear(width, size), nn.ReLU()]
                width = size
            return nn.Sequential(*layers, nn.Linear(width, outputs))

        self.actor = mlp(observation_dim, 2 * action_dim)
        self.critics = nn.ModuleList(mlp(observation_dim + action_dim, 1) for _ in range(2))
        self.targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.log_alpha = nn.Parameter(torch.zeros(()))
        self.gamma, self.tau, self.target_entropy = cfg.sac.gamma, cfg.sac.tau, -action_dim / 2
        lr = cfg.sac.lr
        self.optimizers = [torch.optim.Adam(self.critics.parameters(), lr=lr, fused=True),
                           torch.optim.Adam(self.actor.parameters(), lr=lr, fused=True),
                           torch.optim.Adam([self.log_alpha], lr=lr, fused=True)]

    def sample(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc, scale = self.actor(observation).chunk(2, -1)
        normal = torch.distributions.Normal(loc, F.softplus(scale) + 1e-4)
        raw = normal.rsample()
        log_prob = (normal.log_prob(raw)
                    - 2 * (torch.log(torch.tensor(2.0)) - raw - F.softplus(-2 * raw))).sum(-1)
        return torch.tanh(raw), log_prob

    def update(self, batch: TensorDict) -> None:
        observation, action = batch["observation"], batch["action"]
        nxt = batch["next"]
        alpha = self.log_alpha.exp()
        with torch.no_grad():
            next_action, next_log_prob = self.sample(nxt["observation"])
            next_input = torch.cat([nxt["observation"], next_action], -1)
            next_q = torch.min(*(target(next_input) for target in self.targets)).squeeze(-1)
            target_q = nxt["reward"].squeeze(-1) + self.gamma * (
                ~nxt["terminated"].squeeze(-1)) * (next_q - alpha * next_log_prob)
        q_input = torch.cat([observation, action], -1)
        q_loss = sum(F.mse_loss(critic(q_input).squeeze(-1), target_q)
                     for critic in self.critics)
        new_action, log_prob = self.sample(observation)
        pi_input = torch.cat([observation, new_action], -1)
        q_new = torch.min(*(critic(pi_input) for critic in self.critics)).squeeze(-1)
        actor_loss = (alpha.detach() * log_prob - q_new).mean()
        alpha_loss = -(self.log_alpha * (log_prob.detach() + self.target_entropy)).mean()
        for optimizer in self.optimizers:
            optimizer.zero_grad(set_to_none=True)
        q_loss.backward()
        self.optimizers[0].step()
        self.optimizers[0].zero_grad(set_to_none=True)  # the actor loss's critic gradients
        (actor_loss + alpha_loss).backward()
        self.optimizers[1].step()
        self.optimizers[2].step()
        with torch.no_grad():
            for target, critic in zip(self.targets, self.critics, strict=True):
                torch._foreach_lerp_(list(target.parameters()), list(critic.parameters()),
                                     self.tau)


def torchrl_sac_update(cfg, actor: nn.Module):
    """TorchRL's SACLoss as its docs build it, for a copy of ``actor``: a ValueOperator MLP
    critic vmapped over two copies, the whole batch, a TD(0) estimator, SoftUpdate, fused Adam."""
    from torchrl.objectives import SACLoss, SoftUpdate

    qvalue = ValueOperator(MLP(in_features=OBSERVATION_DIM + ACTION_DIM,
                               num_cells=list(cfg.sac.hidden_sizes), out_features=1,
                               activation_class=nn.ReLU), in_keys=["action", "observation"])
    loss = SACLoss(copy.deepcopy(actor), qvalue, num_qvalue_nets=2, loss_function="l2",
                   alpha_init=cfg.sac.alpha_init, target_entropy=-ACTION_DIM / 2,
                   delay_qvalue=True)
    loss.make_value_estimator(gamma=cfg.sac.gamma)
    target = SoftUpdate(loss, tau=cfg.sac.tau)
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg.sac.lr, fused=True)

    def update(batch: TensorDict) -> None:
        losses = loss(batch)
        (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        target.step()

    return update


def cycling(update, batches: list[TensorDict]):
    """``update`` on the next of ``batches`` at every call (sampling not timed)."""
    calls = itertools.count()
    return lambda: update(batches[next(calls) % len(batches)])


def sac_rows(tmp: Path, quick: bool, mode: str | None, rounds: int = 5) -> list[dict]:
    """The recipe's SAC update, eager and compiled, against its bound, its matmuls alone,
    TorchRL's SACLoss and plain PyTorch. Eager, compiled and the GEMM rate are timed in
    ``rounds`` alternating rounds, so that each round's fraction of the bound divides by the
    GEMM rate of the same minutes (this VM's load moves both); the medians are shown."""
    minimum = 1.0 if quick else 4.0
    setup = training_setup(tmp, 256)
    batches = [setup["buffer"].sample() for _ in range(8)]
    recipe = cycling(setup["update_sac"], batches)
    flops = counted_flops(recipe)
    matmul_seconds = seconds_per_call(matmuls_alone(recipe), min_seconds=minimum,
                                      warmup_calls=5)
    torchrl_seconds = seconds_per_call(cycling(torchrl_sac_update(setup["cfg"], setup["actor"]),
                                               batches),
                                       min_seconds=minimum, warmup_calls=5)
    plain = PlainSAC(setup["cfg"])
    plain_seconds = seconds_per_call(cycling(plain.update, batches), min_seconds=minimum,
                                     warmup_calls=5)
    compiled_update = cycling(training_setup(tmp, 256, "compile.enabled=true",
                                             f"compile.mode={mode or 'null'}")["update_sac"],
                              batches)
    start = time.perf_counter()
    for _ in range(3):
        compiled_update()
    compile_seconds = time.perf_counter() - start
    times = alternating_seconds({"eager": recipe, "compiled": compiled_update, "gemm": gemm()},
                                2 if quick else rounds, minimum / 2)
    peaks = [GEMM_FLOPS / seconds for seconds in times["gemm"]]
    recipe_seconds, compiled_seconds = (statistics.median(times[key])
                                        for key in ("eager", "compiled"))
    speedups = [e / c for e, c in zip(times["eager"], times["compiled"], strict=True)]
    rounds_done = len(times["eager"])
    print(f"sac: {flops / 1e9:.3f} GFLOP; compiled in {compile_seconds:.0f} s", flush=True)
    return [
        bound_row_by_round(f"SAC update, recipe, eager, median of {rounds_done} rounds (ms)",
                           times["eager"], flops, peaks),
        bound_row_by_round(f"SAC update, recipe compiled ({mode}; compile "
                           f"{compile_seconds:.0f} s), median of {rounds_done} rounds (ms)",
                           times["compiled"], flops, peaks),
        {"measure": f"SAC update, recipe compiled ({mode}), median of {rounds_done} rounds "
                    "(ms)", "project": 1000 * compiled_seconds,
         "reference": 1000 * recipe_seconds,
         "reference is": f"the recipe's eager update, alternating (speed-up {spread(speedups)})",
         "ratio": statistics.median(speedups)},
        matmul_row("SAC update, recipe, eager (ms)", recipe_seconds, matmul_seconds),
        {"measure": "SAC update, recipe, eager (ms)", "project": 1000 * recipe_seconds,
         "reference": 1000 * torchrl_seconds,
         "reference is": "TorchRL SACLoss as documented (vmap critics, whole batch)",
         "ratio": torchrl_seconds / recipe_seconds},
        {"measure": "SAC update, recipe, eager (ms)", "project": 1000 * recipe_seconds,
         "reference": 1000 * plain_seconds, "reference is": "plain PyTorch (CleanRL's shape)",
         "ratio": plain_seconds / recipe_seconds},
    ]


# --------------------------------------------------------------------------- heads
def term_by_term_update(trainer):
    """The trainer's FuRL and D3 losses (stage 2) scored one term at a time through the
    reward's own calls, one backward and one Adam step per loss: the trainer before its terms
    were joined into one batch per head."""
    reward = trainer.reward
    positional, directional = trainer.losses
    goal = directional.goal_image_embedding

    def r_p(states):
        return reward.positional_reward(states["embedding"], states["initial_embedding"],
                                        states["previous_embedding"])

    def r_d(end, start, states, position=None):
        return reward.directional_reward(end, start, states["initial_embedding"],
                                         position=position)

    def losses(batch: TensorDict) -> tuple[torch.Tensor, torch.Tensor]:
        negative, positive, pair = batch["negative"], batch["positive"], batch["positive_pair"]
        loss_p = (ranking_loss(r_p(positive), r_p(negative), positional.delta).mean()
                  + ranking_loss(r_p(pair["later"]), r_p(pair["earlier"]),
                                 positional.delta).mean())
        n_t, n_tk = negative["embedding"], negative["previous_embedding"]
        p_t, p_tk = positive["embedding"], positive["previous_embedding"]
        loss_d = (r_d(n_t, n_tk, negative).mean()
                  - r_d(goal.expand_as(n_t), n_t, negative, n_t).mean()
                  + r_d(p_tk, p_t, positive, p_t).mean() - r_d(p_t, p_tk, positive).mean())
        return loss_p, loss_d

    def update() -> None:
        batch = trainer.replay.sample(trainer.batch_size)
        for loss, optimizer in zip(losses(batch), trainer.optimizers, strict=True):
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()

    return update, losses


def heads_rows(tmp: Path, quick: bool, peak: float) -> list[dict]:
    minimum = 1.0 if quick else 4.0
    rows = []
    for dim in (1024, 256):
        setup = training_setup(tmp, dim)
        trainer = setup["trainer"]
        reference, losses = term_by_term_update(trainer)
        batch = trainer.replay.sample(trainer.batch_size)
        joined = [loss(batch)[loss.loss_key] for loss in trainer.losses]
        for value, expected in zip(joined, losses(batch), strict=True):  # the same losses
            torch.testing.assert_close(value, expected, rtol=1e-4, atol=1e-5)
        flops = counted_flops(trainer.update)
        seconds = seconds_per_call(trainer.update, min_seconds=minimum, warmup_calls=5)
        reference_seconds = seconds_per_call(reference, min_seconds=minimum, warmup_calls=5)
        matmul_seconds = seconds_per_call(matmuls_alone(trainer.update), min_seconds=minimum,
                                          warmup_calls=5)
        measure = f"reward-head update, FuRL + D3, stage 2, D={dim}, eager (ms)"
        rows += [bound_row(measure, seconds, flops, peak),
                 matmul_row(measure, seconds, matmul_seconds),
                 {"measure": measure, "project": 1000 * seconds,
                  "reference": 1000 * reference_seconds,
                  "reference is": "term by term, one backward per loss",
                  "ratio": reference_seconds / seconds}]
    return rows


# --------------------------------------------------------------------------- step
def compiled_regions(tmp: Path) -> list:
    """The parts of the step that ``compile.enabled`` compiles, eager, each on a fixed batch:
    the reward-head losses' forward and backward, the relabelling's reward call and the SAC
    update."""
    setup = training_setup(tmp, 1024)
    trainer, buffer = setup["trainer"], setup["buffer"]
    batch = trainer.replay.sample(trainer.batch_size)
    relabel = buffer.transform[-1]
    transitions = buffer.sample()

    def losses() -> None:
        torch.stack([loss(batch)[loss.loss_key] for loss in trainer.losses]).sum().backward()

    return [losses, lambda: relabel(transitions), lambda: setup["update_sac"](transitions)]


def step_rows(tmp: Path, quick: bool, mode: str | None, repeats: int) -> list[dict]:
    """Eager and compiled against the bound, each build against the GEMM rate measured just
    before it; compiled against eager in ``repeats`` fresh builds (dynamo reset before each, so
    each compiles anew; inductor's on-disk cache serves the later ones, and the first too when
    an earlier run on the machine filled it)."""
    minimum = 1.0 if quick else 4.0
    step = training_step(False, tmp)
    flops = counted_flops(step)
    matmul_seconds = seconds_per_call(matmuls_alone(step), min_seconds=minimum, warmup_calls=5)
    # What compile could give if it removed everything but the matmuls of what it compiles.
    regions = compiled_regions(tmp)
    region_seconds = sum(seconds_per_call(fn, min_seconds=minimum, warmup_calls=5)
                         for fn in regions)
    region_matmul_seconds = sum(seconds_per_call(matmuls_alone(fn), min_seconds=minimum,
                                                 warmup_calls=5) for fn in regions)
    eager_times, compiled_times, compile_times, peaks = [], [], [], []
    for _ in range(repeats):
        peaks.append(gemm_flops_per_second(min_seconds=minimum / 4))
        torch._dynamo.reset()
        eager = training_step(False, tmp)
        eager_times.append(seconds_per_call(eager, min_seconds=minimum, warmup_calls=5))
        compiled = training_step(True, tmp, mode)
        start = time.perf_counter()
        for _ in range(3):  # compilation, and the recompile at the first stage-2 graph
            compiled()
        compile_times.append(time.perf_counter() - start)
        compiled_times.append(seconds_per_call(compiled, min_seconds=minimum, warmup_calls=5))
        print(f"step: eager {1000 * eager_times[-1]:.1f} ms, compiled "
              f"{1000 * compiled_times[-1]:.1f} ms (compiled in {compile_times[-1]:.0f} s)",
              flush=True)
    speedups = sorted(e / c for e, c in zip(eager_times, compiled_times, strict=True))
    eager_seconds = statistics.median(eager_times)
    ceiling = eager_seconds / (eager_seconds - region_seconds + region_matmul_seconds)
    return [
        bound_row_by_round(f"training step, eager, median of {repeats} builds (ms)",
                           eager_times, flops, peaks),
        matmul_row(f"training step, eager, median of {repeats} (ms)", eager_seconds,
                   matmul_seconds),
        bound_row_by_round(f"training step, compiled ({mode}), median of {repeats} builds (ms)",
                           compiled_times, flops, peaks),
        {"measure": f"training step, compiled vs eager (speed-up, {repeats} builds: "
                    f"{spread(speedups)}; compile {compile_times[0]:.0f} s in the first build, "
                    f"{statistics.median(compile_times[1:] or compile_times):.0f} s in the "
                    "others)",
         "project": speedups[0], "reference": 1.0, "reference is": "eager (min shown)",
         "ratio": speedups[0]},
        {"measure": f"training step, compile's ceiling: eager with the compiled parts "
                    f"({1000 * region_seconds:.1f} ms eager) cut to their matmuls "
                    f"({1000 * region_matmul_seconds:.1f} ms) (speed-up)",
         "project": ceiling, "reference": 1.0, "reference is": "eager", "ratio": ceiling},
    ]


# --------------------------------------------------------------------------- loop
ENCODERS = {  # name: (overrides, episode length, quick episode length)
    "state encoder, D=1024": (("encoder.name=state", "+encoder.options.dim=1024"), 100, 20),
    "shipped encoder, 64 px": (("encoder.name=metaworld_small", "env.image_size=64"), 100, 20),
    "random LIV, 224 px": (("encoder.name=liv", "env.image_size=224"), 24, 8),
}


def steady_steps_per_second(cfg_overrides: list[str], num_envs: int, length: int,
                            tmp: Path) -> float:
    """Env steps/s over the 3rd and 4th rounds of ``num_envs`` episodes of one run, timed at
    the episode ends the recipe logs (the first round has no updates, the second compiles)."""
    clock: dict[int, float] = {}
    log_metrics = sac_temporal.log_metrics

    def timed(logger, metrics: dict, step: int) -> None:
        if "train/success" in metrics:
            clock[step] = time.perf_counter()
        log_metrics(logger, metrics, step)

    cfg = recipe_config(tmp / f"loop_{next(RUN_IDS)}", *cfg_overrides,
                        f"env.num_envs={num_envs}", f"env.max_episode_steps={length}",
                        "train.episodes=" + str(4 * num_envs))
    sac_temporal.log_metrics = timed
    try:
        sac_temporal.train(cfg)
    finally:
        sac_temporal.log_metrics = log_metrics
    second, fourth = 2 * num_envs * length, 4 * num_envs * length
    return (fourth - second) / (clock[fourth] - clock[second])


def loop_rows(tmp: Path, quick: bool, skip_liv: bool, mode: str | None) -> list[dict]:
    from temporal_torchrl.encoders import save_random_liv_checkpoint

    checkpoint = tmp / "liv.pt"
    save_random_liv_checkpoint(checkpoint)
    rows = []
    for name, (overrides, length, quick_length) in ENCODERS.items():
        if skip_liv and "LIV" in name:
            continue
        overrides = [*overrides] + ([f"encoder.checkpoint={checkpoint}"] if "LIV" in name
                                    else [])
        length = quick_length if quick else length
        today = None
        for compiled in (False, True):
            for num_envs in ((1, 2) if quick else (1, 2, 4)):
                rate = steady_steps_per_second(
                    [*overrides, f"compile.enabled={str(compiled).lower()}",
                     f"compile.mode={mode or 'null'}"], num_envs, length, tmp)
                today = rate if today is None else today
                print(f"loop: {name}, {num_envs} envs, compiled={compiled}: {rate:.1f}/s",
                      flush=True)
                rows.append({"measure": f"whole loop, {name}, {num_envs} env(s), "
                                        f"{'compiled' if compiled else 'eager'} (env steps/s)",
                             "project": rate, "reference": today,
                             "reference is": "one env, eager (today's loop)",
                             "ratio": rate / today})
        if torch.cuda.is_available() and "LIV" in name and not quick:
            # The GPU row: everything on the GPU, 16 rendering workers, compiled updates.
            rate = steady_steps_per_second(
                [*overrides, "train.device=cuda", "compile.enabled=true",
                 f"compile.mode={mode or 'null'}"], 16, length, tmp)
            rows.append({"measure": f"whole loop, {name}, 16 envs, compiled, "
                                    f"{torch.cuda.get_device_name(0)} (env steps/s)",
                         "project": rate, "reference": today,
                         "reference is": "one env, eager, CPU (today's loop)",
                         "ratio": rate / today})
    return rows


#: The default run's loop: the shipped encoder at 64 px, FuRL + D3, stage 1 (relay on), 1 env.
DEFAULT_LOOP = ("encoder.name=metaworld_small", "env.image_size=64")


def default_loop_rows(tmp: Path, quick: bool, compile_mode: str | None = None) -> list[dict]:
    """The default loop's rate, eager, or compiled with ``compile_mode`` when it is given."""
    compiled = ["compile.enabled=true", f"compile.mode={compile_mode}"] if compile_mode else []
    rate = steady_steps_per_second([*DEFAULT_LOOP, *compiled], 1, 20 if quick else 100, tmp)
    how = f"compiled ({compile_mode})" if compile_mode else "eager"
    return [{"measure": f"whole default loop, shipped encoder 64 px, 1 env, {how} (env steps/s)",
             "project": rate, "reference": float("nan"), "reference is": "-",
             "ratio": float("nan")}]


def fresh_default_loop(tmp: Path, quick: bool, tree: Path,
                       compile_mode: str | None = None) -> float:
    """The default loop's rate (compiled with ``compile_mode`` when given), measured by this
    script in a fresh process on ``tree``'s recipe and package (``TEMPORAL_TORCHRL_TREE``)."""
    out = tmp / f"default_{next(RUN_IDS)}.json"
    compiled = ["--compile-mode", compile_mode, "--default-compiled"] if compile_mode else []
    subprocess.run([sys.executable, __file__, "--sections", "default", "--json", str(out),
                    "--threads", str(torch.get_num_threads()), *(["--quick"] if quick else []),
                    *compiled],
                   env={**os.environ, "TEMPORAL_TORCHRL_TREE": str(tree)}, check=True)
    return json.loads(out.read_text())["rows"][0]["project"]


def baseline_rows(tmp: Path, quick: bool, revision: str | None, peak: float,
                  compile_mode: str | None, rounds: int = 3) -> list[dict]:
    """The default loop here, eager and compiled (``compile_mode``), and (``revision``) at that
    git revision, each in a fresh process (the revision's from a worktree), alternating,
    ``rounds`` times each; and the most that faster updates could give it: its env side (the
    same loop without updates) plus its updates' FLOPs at the GEMM rate."""
    length = 20 if quick else 100
    ours, compiled, theirs = [], [], []
    if revision is not None:
        worktree = tmp / "baseline"
        added = subprocess.run(["git", "-C", str(TREE), "worktree", "add", "--detach",
                                str(worktree), revision], capture_output=True, text=True)
        if added.returncode != 0:
            raise SystemExit(f"--baseline-rev {revision!r}: git could not check it out "
                             f"({added.stderr.strip()}); pass a commit, tag or branch of "
                             f"{TREE}, e.g. --baseline-rev HEAD~1.")
    try:
        for _ in range(rounds):
            ours.append(fresh_default_loop(tmp, quick, TREE))
            compiled.append(fresh_default_loop(tmp, quick, TREE, compile_mode))
            print(f"default loop: {ours[-1]:.1f} eager, {compiled[-1]:.1f} compiled", flush=True)
            if revision is None:
                continue
            theirs.append(fresh_default_loop(tmp, quick, worktree))
            print(f"default loop: {ours[-1]:.1f} here, {theirs[-1]:.1f} at {revision}",
                  flush=True)
    finally:
        if revision is not None:
            subprocess.run(["git", "-C", str(TREE), "worktree", "remove", "--force",
                            str(worktree)], check=False, capture_output=True)
    here = statistics.median(ours)
    today, today_is = ((statistics.median(theirs), f"the same loop at {revision}")
                       if revision is not None else (here, "the loop here"))
    env_rate = steady_steps_per_second(
        [*DEFAULT_LOOP, "train.utd_ratio=0", "train.reward_updates_per_step=0"], 1, length, tmp)
    # Per env step in stage 1 with relay: one head update, one SAC batch, two SAC updates.
    setup = training_setup(tmp, 256, stage=1)
    batch = setup["buffer"].sample()
    updates = (setup["trainer"].update, setup["buffer"].sample,
               lambda: setup["update_sac"](batch))
    weights = (1, 1, 2)
    flops = sum(n * counted_flops(fn) for n, fn in zip(weights, updates, strict=True))
    bound = 1.0 / (1.0 / env_rate + flops / peak)
    matmul_seconds = sum(n * seconds_per_call(matmuls_alone(fn), min_seconds=2.0,
                                              warmup_calls=5)
                         for n, fn in zip(weights, updates, strict=True))
    ceiling = 1.0 / (1.0 / env_rate + matmul_seconds)
    print(f"default loop: env side {env_rate:.1f} steps/s, updates {flops / 1e9:.2f} GFLOP a "
          "step", flush=True)
    speedups = [c / e for c, e in zip(compiled, ours, strict=True)]
    rows = [{"measure": f"whole default loop, shipped encoder 64 px, 1 env, eager, median of "
                        f"{rounds} (env steps/s)", "project": here, "reference": today,
             "reference is": today_is, "ratio": here / today},
            {"measure": f"whole default loop, compiled ({compile_mode}), median of {rounds} "
                        "alternating with eager (env steps/s; steady state, compile time not "
                        "in it)", "project": statistics.median(compiled), "reference": here,
             "reference is": f"the loop here, eager (speed-up by round: {spread(speedups)})",
             "ratio": statistics.median(compiled) / here},
            {"measure": f"whole default loop, bound: its env side ({env_rate:.1f} steps/s "
                        f"without updates) + {flops / 1e9:.2f} GFLOP of updates a step at "
                        f"{peak / 1e9:.0f} GFLOP/s (env steps/s)", "project": bound,
             "reference": today, "reference is": today_is, "ratio": bound / today},
            {"measure": f"whole default loop, ceiling: its env side + its updates' matmuls "
                        f"alone ({1000 * matmul_seconds:.1f} ms a step) (env steps/s)",
             "project": ceiling, "reference": today, "reference is": today_is,
             "ratio": ceiling / today}]
    return rows


def sequence_head_rows(tmp: Path, quick: bool, rounds: int = 5) -> list[dict]:
    """The reward-head update and the training step (head update, SAC batch and relabelling,
    SAC update) with d_sequence (K = 8) against D3, FuRL beside each, D = 1024, stage 1 and 2:
    ``rounds`` alternating timings of the two in one process, the medians."""
    rows = []
    for stage in (1, 2):
        setups = {variant: training_setup(tmp, 1024, f"reward.directional={variant}",
                                          stage=stage) for variant in ("d3", "d_sequence")}

        def step(setup: dict):
            def run() -> None:
                setup["trainer"].update()
                setup["update_sac"](setup["buffer"].sample())
            return run

        for part, make in (("reward-head update", lambda setup: setup["trainer"].update),
                           ("training step", step)):
            times = alternating_seconds({variant: make(setup) for variant, setup in setups.items()},
                                        2 if quick else rounds, 0.3 if quick else 1.0)
            d3, sequence = (1e3 * statistics.median(times[variant]) for variant in setups)
            print(f"{part}, stage {stage}: d_sequence {sequence:.1f} ms, D3 {d3:.1f} ms",
                  flush=True)
            rows.append({"measure": f"{part}, FuRL + d_sequence K=8, stage {stage}, D=1024, "
                                    f"eager, median of {len(times['d3'])} alternating (ms)",
                         "project": sequence, "reference": d3,
                         "reference is": "FuRL + D3, the same batch size and buffer",
                         "ratio": sequence / d3})
    return rows


def sequence_rows(tmp: Path, quick: bool, rounds: int = 3) -> list[dict]:
    """d_sequence (K = 8) against D3 in the same loop: state encoder D = 1024, 1 env, eager;
    ``rounds`` runs of each, alternating, and the medians."""
    length = 20 if quick else 100
    common = ["encoder.name=state", "+encoder.options.dim=1024"]
    d3, sequence = [], []
    for _ in range(rounds):
        d3.append(steady_steps_per_second([*common, "reward.directional=d3"], 1, length, tmp))
        sequence.append(steady_steps_per_second([*common, "reward.directional=d_sequence"], 1,
                                                length, tmp))
        print(f"d_sequence: {sequence[-1]:.1f}, D3: {d3[-1]:.1f} env steps/s", flush=True)
    ratios = sorted(a / b for a, b in zip(d3, sequence, strict=True))
    return [{"measure": f"whole loop, d_sequence K=8, state encoder D=1024, 1 env, eager, median "
                        f"of {rounds} alternating (env steps/s; ratio: D3's rate over it, the "
                        f"cost per env step; per round {' / '.join(f'{r:.2f}' for r in ratios)})",
             "project": statistics.median(sequence), "reference": statistics.median(d3),
             "reference is": "D3, the same loop",
             "ratio": statistics.median(d3) / statistics.median(sequence)}]


# --------------------------------------------------------------------------- reference
def plain_sac_steps_per_second(cfg, episodes: int) -> float:
    """The reference: TorchRL env.step + per-step buffer extend + SACLoss update, no VLM."""
    env = make_env(cfg.env.task, cfg.env.seed, max_episode_steps=cfg.env.max_episode_steps)
    actor, _ = factories.make_sac_agent(cfg, env)
    update = torchrl_sac_update(cfg, actor)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(episodes * 1000),
                                    batch_size=cfg.sac.batch_size)
    steps = 0
    start = time.perf_counter()
    for _ in range(episodes):
        tensordict = env.reset()
        for _ in range(cfg.env.max_episode_steps):
            with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
                actor(tensordict)
            tensordict = env.step(tensordict)
            buffer.add(tensordict.select("observation", "action", "next"))
            steps += 1
            if steps > cfg.env.max_episode_steps:  # the recipe updates from its 2nd episode on
                update(buffer.sample())
            if tensordict["next", "done"].item():
                break
            tensordict = step_mdp(tensordict)
    return steps / (time.perf_counter() - start)


def reference_rows(tmp: Path, quick: bool) -> list[dict]:
    episodes, length = (3, 100) if quick else (4, 250)
    cfg = recipe_config(tmp / "sac", f"train.episodes={episodes}",
                        f"env.max_episode_steps={length}", "reward.positional=none",
                        "reward.directional=none")
    summary = sac_temporal.train(cfg)
    reference = plain_sac_steps_per_second(cfg, episodes)
    return [{"measure": "whole loop, no VLM reward (env steps/s)",
             "project": summary["steps_per_second"], "reference": reference,
             "reference is": "plain TorchRL SAC loop",
             "ratio": summary["steps_per_second"] / reference}]


# --------------------------------------------------------------------------- replay
def filled_buffers(transitions: int, dim: int = 1024, episode_length: int = 500):
    """The project's buffer and a TorchRL SliceSampler buffer, both with ``transitions``."""
    episodes = transitions // episode_length
    ours = EpisodeReplayBuffer(capacity=episodes * (episode_length + 1), history=5,
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


def replay_rows(quick: bool) -> list[dict]:
    transitions = 500_000
    ours, reference = filled_buffers(transitions)
    minimum = 0.5 if quick else 2.0
    ours_seconds = seconds_per_call(lambda: ours.sample(256), min_seconds=minimum)
    reference_seconds = seconds_per_call(lambda: reference.sample(), min_seconds=minimum)
    finetuning_seconds = seconds_per_call(lambda: ours.finetuning.sample(256),
                                          min_seconds=minimum)
    naive = transitions * (2 * 1024 * 4 + 2 * 39 * 4 + 4 * 4 + 4)
    slice_reference = "SliceSampler(slice_len=2), float16 embeddings"
    return [
        {"measure": "sample 256 transitions + histories at 500k (ms)",
         "project": 1000 * ours_seconds, "reference": 1000 * reference_seconds,
         "reference is": slice_reference, "ratio": ours_seconds / reference_seconds},
        {"measure": "finetuning batch (256 negatives, positives, pairs) at 500k (ms)",
         "project": 1000 * finetuning_seconds, "reference": 1000 * reference_seconds,
         "reference is": slice_reference, "ratio": finetuning_seconds / reference_seconds},
        {"measure": "replay memory at 500k transitions, D=1024 (GB)",
         "project": ours.memory_bytes() / 1e9, "reference": naive / 1e9,
         "reference is": "s_t and s_t+1 as float32 (computed)",
         "ratio": ours.memory_bytes() / naive},
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    parser.add_argument("--quick", action="store_true", help="shorter timings (smoke runs)")
    parser.add_argument("--sections", default=",".join(SECTIONS),
                        help=f"comma-separated subset of {', '.join(SECTIONS)}, or default "
                             "(the default loop alone)")
    parser.add_argument("--threads", type=int, default=os.cpu_count(),
                        help="torch threads (default: all cores)")
    parser.add_argument("--skip-liv", action="store_true", help="no LIV loop rows")
    parser.add_argument("--compile-mode", default="max-autotune",
                        help="torch.compile mode of the compiled rows (default: max-autotune, "
                             "the mode that pays off on a CPU)")
    parser.add_argument("--repeats", type=int, default=5,
                        help="fresh eager and compiled builds of the step section (default 5)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="alternating loop runs of d_sequence and D3 in the sequence "
                             "section (default 3)")
    parser.add_argument("--default-compiled", action="store_true",
                        help="the default section's loop compiled (--compile-mode); the loop "
                             "section runs it so, alternating with eager")
    parser.add_argument("--baseline-rev", default=None,
                        help="git revision whose default loop the loop section measures too")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats {args.repeats}: expected an integer >= 1 (fresh builds of "
                     "the step section).")
    if args.rounds < 1:
        parser.error(f"--rounds {args.rounds}: expected an integer >= 1 (loop runs of each "
                     "reward in the sequence section).")
    sections = args.sections.split(",")
    if unknown := set(sections) - {*SECTIONS, "default"}:
        parser.error(f"unknown sections {sorted(unknown)}; choose from {', '.join(SECTIONS)}")
    torch.set_num_threads(args.threads)
    print(f"machine: {machine_description()}; package: "
          f"{Path(temporal_torchrl.__file__).parent}", flush=True)
    rows = []
    peak = (gemm_flops_per_second() if {"heads", "loop"} & set(sections)
            else float("nan"))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "sac" in sections:
            rows += sac_rows(tmp, args.quick, args.compile_mode)
        if "heads" in sections:
            rows += heads_rows(tmp, args.quick, peak)
        if "step" in sections:
            rows += step_rows(tmp, args.quick, args.compile_mode, args.repeats)
        if "default" in sections:
            rows += default_loop_rows(tmp, args.quick,
                                      args.compile_mode if args.default_compiled else None)
        if "loop" in sections:
            rows += baseline_rows(tmp, args.quick, args.baseline_rev, peak, args.compile_mode)
        if "sequence" in sections:
            rows += sequence_head_rows(tmp, args.quick)
            rows += sequence_rows(tmp, args.quick, args.rounds)
        if "grid" in sections:
            rows += loop_rows(tmp, args.quick, args.skip_liv, args.compile_mode)
        if "reference" in sections:
            rows += reference_rows(tmp, args.quick)
    if "replay" in sections:
        rows += replay_rows(args.quick)
    report("Training updates, step, whole loop and replay buffer", rows, args.json)


if __name__ == "__main__":
    main()
