"""Training throughput: the training step against the compute bound, the whole loop, the replay.

Sections (``--sections``, default all), each row next to its reference measured in the same run:

step    the training step alone, as the recipe runs it: one reward-head update (FuRL's ranking
        loss and D3's directional loss, stage 2: every loss term active), one SAC batch sampled
        and relabelled, one SAC update; batch 256, D = 1024. Eager and compiled
        (``torch.compile``), each against the compute bound: the step's FLOPs (counted by
        ``torch.profiler`` with ``with_flops=True``: matmuls) divided by this machine's fp32 GEMM
        throughput (a 2048^3 matmul, measured); the achieved fraction of that bound.
loop    the whole recipe (``recipes/sac_temporal.py``'s ``train``), env steps/s in the steady
        state (the 3rd and 4th rounds of ``num_envs`` episodes, timed at the episode ends: the
        1st round has no updates, the 2nd compiles) for the state encoder (D = 1024), the
        shipped encoder at 64 px and a random-weight LIV at 224 px; ``env.num_envs`` 1, 2
        and 4, eager and compiled; against today's loop (one env, eager) of the same encoder;
        with CUDA also LIV with 16 envs, everything on the GPU, compiled.
reference  the recipe without a VLM reward against a plain TorchRL SAC loop on the same env
        (TensorDictReplayBuffer, same networks and schedule): the recipe's own overhead.
replay  sampling 256 transitions with their histories at 500,000 transitions (D = 1024) against
        TorchRL's SliceSampler(slice_len=2) on the same float16 embeddings; a stage-2 finetuning
        batch; the replay memory against storing s_t and s_{t+1} in float32.

``--threads`` sets torch's threads (default: all cores). ``--quick`` shortens everything.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import torch
from _common import machine_description, report, seconds_per_call
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torch.profiler import ProfilerActivity, profile
from torchrl.data import LazyTensorStorage, SliceSampler, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
sys.path.insert(0, str(RECIPES))

import sac_temporal  # noqa: E402

from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows  # noqa: E402
from temporal_torchrl.envs import make_env  # noqa: E402
from temporal_torchrl.training import factories  # noqa: E402

SECTIONS = ("step", "loop", "reference", "replay")


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
def training_step(compiled: bool, tmp: Path, mode: str | None = None):
    """The recipe's step (head update, SAC batch + relabel, SAC update) on a stage-2 buffer."""
    cfg = recipe_config(tmp / "step", "encoder.name=state", "+encoder.options.dim=1024",
                        f"compile.enabled={str(compiled).lower()}",
                        f"compile.mode={mode or 'null'}")
    torch.manual_seed(0)
    encoder = factories.make_encoder(cfg)
    reward = factories.make_reward(cfg, encoder)
    env = factories.make_environment(cfg, None, None)
    actor, qvalue = factories.make_sac_agent(cfg, env)
    env.close()
    loss, target_updater, optimizer = factories.make_sac_loss(cfg, actor, qvalue, 4)
    update_sac = factories.make_sac_update(cfg, loss, target_updater, optimizer)
    buffer = factories.make_replay_buffer(cfg, 20 * 501, reward)
    buffer.extend(episode_rows(synthetic_episode(500, 1024, success_from=300)))
    for _ in range(9):
        buffer.extend(episode_rows(synthetic_episode(500, 1024)))
    trainer = factories.make_reward_trainer(cfg, reward, torch.randn(1024), buffer)
    assert trainer.stage == 2

    def step() -> None:
        trainer.update()
        update_sac(buffer.sample())

    return step


def gemm_flops_per_second(size: int = 2048) -> float:
    a, b = torch.randn(size, size), torch.randn(size, size)
    seconds = seconds_per_call(lambda: a @ b, min_seconds=2.0)
    return 2 * size ** 3 / seconds


def step_rows(tmp: Path, quick: bool, mode: str | None) -> list[dict]:
    minimum = 1.0 if quick else 5.0
    eager = training_step(False, tmp)
    eager()
    with profile(activities=[ProfilerActivity.CPU], with_flops=True) as profiler:
        eager()
    flops = sum(event.flops for event in profiler.key_averages())
    peak = gemm_flops_per_second()
    bound = flops / peak
    eager_seconds = seconds_per_call(eager, min_seconds=minimum, warmup_calls=5)
    compiled = training_step(True, tmp, mode)
    start = time.perf_counter()
    for _ in range(3):  # compilation, and the recompile at the first stage-2 graph
        compiled()
    compile_seconds = time.perf_counter() - start
    compiled_seconds = seconds_per_call(compiled, min_seconds=minimum, warmup_calls=5)
    print(f"step: {flops / 1e9:.3f} GFLOP, GEMM {peak / 1e9:.1f} GFLOP/s, compile "
          f"{compile_seconds:.0f} s", flush=True)
    reference = f"compute bound: {flops / 1e9:.2f} GFLOP / {peak / 1e9:.0f} GFLOP/s GEMM"
    return [
        {"measure": "training step, eager (ms)", "project": 1000 * eager_seconds,
         "reference": 1000 * bound, "reference is": reference,
         "ratio": bound / eager_seconds},
        {"measure": "training step, compiled (ms)", "project": 1000 * compiled_seconds,
         "reference": 1000 * bound, "reference is": reference,
         "ratio": bound / compiled_seconds},
        {"measure": "training step, compiled vs eager (speed-up)",
         "project": eager_seconds / compiled_seconds, "reference": 1.0,
         "reference is": "eager", "ratio": eager_seconds / compiled_seconds},
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

    cfg = recipe_config(tmp / f"loop_{len(os.listdir(tmp))}", *cfg_overrides,
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


# --------------------------------------------------------------------------- reference
def plain_sac_steps_per_second(cfg, episodes: int) -> float:
    """The reference: TorchRL env.step + per-step buffer extend + SACLoss update, no VLM."""
    env = make_env(cfg.env.task, cfg.env.seed, max_episode_steps=cfg.env.max_episode_steps)
    actor, qvalue = factories.make_sac_agent(cfg, env)
    loss, updater, optimizer = factories.make_sac_loss(cfg, actor, qvalue, 4)
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
                losses = loss(buffer.sample())
                optimizer.zero_grad()
                (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
                optimizer.step()
                updater.step()
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
                        help=f"comma-separated subset of {', '.join(SECTIONS)}")
    parser.add_argument("--threads", type=int, default=os.cpu_count(),
                        help="torch threads (default: all cores)")
    parser.add_argument("--skip-liv", action="store_true", help="no LIV loop rows")
    parser.add_argument("--compile-mode", default="max-autotune",
                        help="torch.compile mode of the compiled rows (default: max-autotune, "
                             "the mode that pays off on a CPU)")
    args = parser.parse_args()
    sections = args.sections.split(",")
    if unknown := set(sections) - set(SECTIONS):
        parser.error(f"unknown sections {sorted(unknown)}; choose from {', '.join(SECTIONS)}")
    torch.set_num_threads(args.threads)
    print(f"machine: {machine_description()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "step" in sections:
            rows += step_rows(tmp, args.quick, args.compile_mode)
        if "loop" in sections:
            rows += loop_rows(tmp, args.quick, args.skip_liv, args.compile_mode)
        if "reference" in sections:
            rows += reference_rows(tmp, args.quick)
    if "replay" in sections:
        rows += replay_rows(args.quick)
    report("Training step, whole loop and replay buffer", rows, args.json)


if __name__ == "__main__":
    main()
