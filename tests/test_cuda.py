"""The CUDA path, end to end: the tests marked ``cuda`` run on a GPU and skip without one, saying
so (``benchmarks/gpu_check.sh`` runs them on a new GPU node).

- the SAC update and the reward-head finetuning losses on CUDA give the CPU's losses, gradients
  and parameters, within float tolerance, from the same weights and the same random draws;
- the embedding transform on CUDA, at a batch of N frames, in float32 and with bf16 autocast
  and channels-last, against the CPU's float32 embeddings;
- a short recipe run with ``train.device=cuda``, ``compile.enabled`` and ``compile.cudagraphs``
  (batches from the CPU storage through pinned memory);
- rendering through EGL with ``env.num_envs=8`` on the GPU, in a child process under a timeout:
  mujoco issue #3444 reports EGL renderers hanging in ``mjr_readPixels`` with 8 spawned envs on
  an H200, and a hang must end as this test's failure, naming it, not as a stuck node.

The unmarked tests are their CPU side, which CI runs: the same comparisons with CPU on both
sides (the helpers, the random-draw harness and the APIs they call), the timeout's kill of a
whole process group, the EGL probe with two envs, and ``benchmarks/gpu_check.sh``'s CPU path
(no GPU: it says so in its JSON and exits 0), its sections' timeouts and budget, and its GPU
sections run on the CPU at smoke sizes.
"""

from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Sequence
from pathlib import Path

import pytest
import sac_temporal
import torch
from helpers import config, make_episode
from tensordict import TensorDict
from torch.utils._python_dispatch import TorchDispatchMode

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.data import EpisodeReplayBuffer, episode_rows
from temporal_torchrl.encoders import LIVEncoder, load_encoder, save_random_liv_checkpoint
from temporal_torchrl.envs import make_temporal_reward
from temporal_torchrl.training import factories
from temporal_torchrl.transforms import EmbeddingTransform

ROOT = Path(__file__).resolve().parents[1]
HAS_CUDA = torch.cuda.is_available()
NO_CUDA = ("no CUDA device: torch.cuda.is_available() is False (torch "
           f"{torch.__version__}, built for CUDA {torch.version.cuda}); the CUDA path is checked "
           "on a GPU node by benchmarks/gpu_check.sh")
cuda = pytest.mark.skipif(not HAS_CUDA, reason=NO_CUDA)

#: The EGL probe's limit with 8 envs on a GPU node: 8 spawned workers importing torch and
#: opening an EGL context take 20-60 s on a node's cores; a hang (mujoco #3444) never ends. Kept
#: short so that a hang leaves gpu_check.sh's five minutes time for its other sections.
EGL_TIMEOUT_S = 90
#: The same probe's limit with 2 envs rendering in software on a busy 2-core CI machine.
CPU_EGL_TIMEOUT_S = 240
#: The GL renderers that draw in software: frames from them mean EGL found no GPU driver.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software")


class HostDraws(TorchDispatchMode):
    """Every random draw on any device comes from one CPU generator, then is copied to the
    draw's device: a CUDA and a CPU run under two of these, seeded alike, take the same draws
    (the devices' own generators would not). Random ops other than ``normal_`` and
    ``uniform_`` are refused, so that no draw is silently left to the device's generator."""

    def __init__(self, seed: int) -> None:
        super().__init__()
        self.generator = torch.Generator().manual_seed(seed)
        self.draws = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func is torch.ops.aten.normal_.default:
            out, mean, std = args[0], *(list(args[1:]) + [0.0, 1.0])[:2]
            host = torch.empty(out.shape, dtype=out.dtype).normal_(
                kwargs.get("mean", mean), kwargs.get("std", std), generator=self.generator)
        elif func is torch.ops.aten.uniform_.default:
            out, low, high = args[0], *(list(args[1:]) + [0.0, 1.0])[:2]
            host = torch.empty(out.shape, dtype=out.dtype).uniform_(
                kwargs.get("from", low), kwargs.get("to", high), generator=self.generator)
        elif torch.Tag.nondeterministic_seeded in func.tags:
            raise NotImplementedError(f"HostDraws does not redirect {func}; add it")
        else:
            return func(*args, **kwargs)
        self.draws += 1
        return out.copy_(host)


def assert_close_on_cpu(actual, expected, rtol: float, atol: float, msg: str) -> None:
    torch.testing.assert_close(actual.detach().cpu(), expected.detach().cpu(), rtol=rtol,
                               atol=atol, msg=msg)


# ---- the SAC update


def sac_updates_on(device: str, tmp_path: Path, updates: int = 3
                   ) -> tuple[list[list[TensorDict]], list[list[torch.Tensor]]]:
    """The recipe's SAC update (eager) on the CPU and on ``device``, from the same weights (made
    on the CPU, copied), on the same batches and draws (:class:`HostDraws`): for each of the two,
    the losses of each update and the parameters after them, on the CPU."""
    cfg = config(tmp_path, "reward.directional=d3", "train.device=cpu")
    env = factories.make_environment(cfg, None, None)
    try:
        batches = [env.rollout(16, break_when_any_done=False) for _ in range(updates)]
        torch.manual_seed(0)
        actor, critics = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    finally:
        env.close()
    losses, parameters = [], []
    for where in ("cpu", device):
        cfg = config(tmp_path, "reward.directional=d3", f"train.device={where}")
        loss, optimizer = factories.make_sac_loss(cfg, copy.deepcopy(actor).to(where),
                                                  copy.deepcopy(critics).to(where), 4)
        update = factories.make_sac_update(cfg, loss, optimizer)
        with HostDraws(seed=1) as draws:
            losses.append([update(batch.clone().to(where)).cpu() for batch in batches])
        assert draws.draws > 0, "the SAC update drew no random numbers through HostDraws"
        parameters.append([p.detach().cpu().clone() for p in loss.parameters()])
    return losses, parameters


def check_sac_update(device: str, tmp_path: Path, rtol: float, atol: float) -> None:
    (cpu_losses, losses), (cpu_parameters, parameters) = sac_updates_on(device, tmp_path)
    for index, (expected, actual) in enumerate(zip(cpu_losses, losses, strict=True)):
        for key in ("loss_actor", "loss_qvalue", "loss_alpha", "entropy"):
            assert_close_on_cpu(actual[key], expected[key], rtol, atol,
                                f"update {index}: {key} on {device} vs cpu")
    for index, (expected, actual) in enumerate(zip(cpu_parameters, parameters, strict=True)):
        assert_close_on_cpu(actual, expected, rtol, atol, f"parameter {index} on {device}")


@pytest.mark.cuda
@cuda
def test_sac_update_on_cuda_matches_the_cpu(tmp_path):
    """Three SAC updates on CUDA (fused Adam, the stacked critics' baddbmm) against the same
    three on the CPU: the same losses and, after them, the same parameters."""
    check_sac_update("cuda", tmp_path, rtol=1e-3, atol=1e-4)


def test_sac_update_comparison_runs_on_the_cpu(tmp_path):
    """The CPU side: the same comparison with the CPU on both sides is exact, so the harness
    (weights copied, batches shared, every draw through HostDraws) gives both runs the same
    inputs, and the update draws its noise through HostDraws."""
    check_sac_update("cpu", tmp_path, rtol=0, atol=0)


# ---- the finetuning losses


def finetuning_losses_on(device: str, tmp_path: Path, stage: int, directional: str
                         ) -> list[tuple[list[torch.Tensor], list[torch.Tensor]]]:
    """The trainer's reward-head losses (FuRL's ranking loss and ``directional``'s loss) on the
    CPU and on ``device``, from the same heads and batch: for each loss, its value and its
    parameters' gradients on each side."""
    dim = 8
    cfg = config(tmp_path, f"reward.directional={directional}")
    torch.manual_seed(0)
    reward = make_temporal_reward("drawer-open", load_encoder("state", dim=dim), k=2,
                                  positional="furl", directional=directional,
                                  options={"window": 4} if directional == "d_sequence" else {})
    buffer = EpisodeReplayBuffer(capacity=200, k=2, window_length=reward.window_length,
                                 gap=5)
    buffer.extend(episode_rows(make_episode(0, 20, dim=dim), embedding_dtype=torch.float32))
    buffer.extend(episode_rows(make_episode(1, 20, successes=(12,) if stage == 2 else (),
                                            dim=dim), embedding_dtype=torch.float32))
    batch = buffer.finetuning.sample(16)
    results = []
    for where in ("cpu", device):
        trainer = factories.make_reward_trainer(cfg, copy.deepcopy(reward).to(where),
                                                torch.ones(dim), buffer)
        assert trainer.stage == stage
        on_device = batch.to(where)
        sides = []
        for loss in trainer.losses:
            parameters = list(loss.parameters())
            value = loss(on_device)[loss.loss_key]
            gradients = torch.autograd.grad(value, parameters, allow_unused=True)
            sides.append(([value.detach().cpu()],
                          [g.cpu() for g in gradients if g is not None]))
        results.append(sides)
    return list(zip(*results, strict=True))


def check_finetuning_losses(device: str, tmp_path: Path, stage: int, directional: str,
                            rtol: float, atol: float) -> None:
    for index, (cpu_side, side) in enumerate(finetuning_losses_on(device, tmp_path, stage,
                                                                  directional)):
        (cpu_value, cpu_gradients), (value, gradients) = cpu_side, side
        assert len(gradients) == len(cpu_gradients) > 0, f"loss {index}: no gradients"
        assert_close_on_cpu(value[0], cpu_value[0], rtol, atol, f"loss {index} on {device}")
        for number, (expected, actual) in enumerate(zip(cpu_gradients, gradients,
                                                        strict=True)):
            assert_close_on_cpu(actual, expected, rtol, atol,
                                f"loss {index}, gradient {number} on {device}")


@pytest.mark.cuda
@cuda
@pytest.mark.parametrize("directional", ["d3", "d_sequence"])
@pytest.mark.parametrize("stage", [1, 2])
def test_finetuning_losses_on_cuda_match_the_cpu(tmp_path, stage, directional):
    """FuRL's ranking loss and the directional loss (D3's MLP, d_sequence's encoder) on CUDA
    give the CPU's values and gradients on the same batch, in both stages."""
    check_finetuning_losses("cuda", tmp_path, stage, directional, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("stage", [1, 2])
def test_finetuning_loss_comparison_runs_on_the_cpu(tmp_path, stage):
    """The CPU side of the comparison, D3, both stages: exact with the CPU on both sides."""
    check_finetuning_losses("cpu", tmp_path, stage, "d3", rtol=0, atol=0)


# ---- the embedding transform


def cosine(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.nn.functional.cosine_similarity(a.float().cpu(), b.float().cpu(), dim=-1)


def embeddings_on(device: str, checkpoint: Path, frames: torch.Tensor,
                  autocast_dtype: torch.dtype | None, channels_last: bool) -> torch.Tensor:
    """The embedding transform's env path (``_call``) on ``device`` for CPU frames ``[N, H, W,
    3]``, as an env hands them over; its embeddings on the CPU, float32."""
    encoder = LIVEncoder(checkpoint, channels_last=channels_last).to(device)
    transform = EmbeddingTransform(encoder, device=torch.device(device),
                                   autocast_dtype=autocast_dtype)
    out = transform._call(TensorDict({"pixels": frames}, batch_size=[len(frames)]))
    assert "pixels" not in out.keys()
    embedding = out["embedding"]
    assert embedding.shape == (len(frames), encoder.dim) and embedding.dtype == torch.float32
    assert torch.isfinite(embedding).all()
    return embedding.cpu()


def check_embeddings(device: str, tmp_path: Path, batch: int, size: int) -> None:
    checkpoint = tmp_path / "liv.pt"
    save_random_liv_checkpoint(checkpoint)
    frames = torch.randint(0, 256, (batch, size, size, 3), dtype=torch.uint8)
    expected = embeddings_on("cpu", checkpoint, frames, None, False)
    float32 = embeddings_on(device, checkpoint, frames, None, False)
    # element by element: the batch's rows in their order, not only their directions
    torch.testing.assert_close(float32, expected, rtol=1e-3, atol=1e-4,
                               msg="float32 on the device vs the CPU")
    assert cosine(float32, expected).min() > 0.9999, "float32 on the device vs the CPU"
    bf16 = embeddings_on(device, checkpoint, frames, torch.bfloat16, True)
    assert cosine(bf16, expected).min() > 0.99, "bf16 autocast + channels-last vs float32"


@pytest.mark.cuda
@cuda
def test_embedding_transform_on_cuda_matches_the_cpu(tmp_path):
    """The LIV-shaped RN50 (random weights in LIV's format) at 224 px, a batch of 64 CPU frames
    embedded on CUDA: float32 the CPU's within float tolerance, row by row; bf16 autocast with
    channels-last within 1e-2 of it in cosine."""
    check_embeddings("cuda", tmp_path, batch=64, size=224)


@pytest.mark.slow
def test_embedding_comparison_runs_on_the_cpu(tmp_path):
    """The CPU side: the same comparison, CPU against CPU (bf16 autocast on the CPU), 2 frames
    at 64 px."""
    check_embeddings("cpu", tmp_path, batch=2, size=64)


# ---- a short recipe run on CUDA


@pytest.mark.cuda
@cuda
def test_recipe_runs_on_cuda_compiled_with_cudagraphs(tmp_path):
    """The recipe with everything on the GPU, the updates compiled and the SAC update captured
    in a CUDA graph (``CudaGraphModule``), the replay storage on the CPU (batches through
    pinned memory): 3 episodes of 20 steps with updates from step 11, FuRL + D3 and relay. It
    runs every update it should, and its losses and returns are finite."""
    overrides = ("reward.directional=d3", "train.device=cuda", "compile.enabled=true",
                 "compile.cudagraphs=true", "replay_buffer.device=cpu",
                 "logger.backend=csv")
    cfg = config(tmp_path, *overrides)
    env = factories.make_environment(cfg, None, None)
    actor, critics = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    env.close()
    loss, optimizer = factories.make_sac_loss(cfg, actor, critics, 4)
    assert type(factories.make_sac_update(cfg, loss, optimizer)).__name__ == "CudaGraphModule"
    summary = sac_temporal.train(config(tmp_path, *overrides))
    assert summary["episodes"] == 3 and summary["env_steps"] == 60
    assert summary["updates"] == 50  # steps 11-60 of 60, one SAC update each (UTD 1)
    metrics = [json.loads(line) for line in
               (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    values = [value for row in metrics for key, value in row.items()
              if isinstance(value, float) and "loss" in key]
    assert values and all(torch.isfinite(torch.tensor(values))), metrics


# ---- EGL rendering with several envs, under a timeout


def run_with_timeout(command: Sequence[str], timeout: float, env: dict | None = None
                     ) -> tuple[int | None, str]:
    """``command`` in a new process session; killed, with every process it started (the
    session's whole group), after ``timeout`` seconds. Its exit status (None when it was
    killed) and its output."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, start_new_session=True, env=env, cwd=ROOT)
    try:
        output, _ = process.communicate(timeout=timeout)
        return process.returncode, output
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        output, _ = process.communicate()
        return None, output


#: Renders drawer-open through EGL in ``argv[1]`` worker envs (64 px, the shipped encoder on
#: ``argv[2]``) for 25 vector steps; prints the GL renderer that EGL gave and the embeddings.
EGL_PROBE = textwrap.dedent("""
    import json, os, sys
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    import torch
    from temporal_torchrl.encoders import load_encoder
    from temporal_torchrl.envs import make_temporal_env
    from mujoco.egl import GLContext
    from OpenGL import GL

    context = GLContext(64, 64)
    context.make_current()
    renderer = GL.glGetString(GL.GL_RENDERER).decode()
    context.free()
    num_envs, device = int(sys.argv[1]), sys.argv[2]
    encoder = load_encoder("metaworld_small", device=device)
    env = make_temporal_env("drawer-open", encoder=encoder, image_size=64,
                            max_episode_steps=10, num_envs=num_envs)
    try:
        rollout = env.rollout(25, break_when_any_done=False)
    finally:
        env.close()
    embedding = rollout["next", "embedding"]
    print("EGL_PROBE " + json.dumps({
        "renderer": renderer, "shape": list(embedding.shape), "dim": encoder.dim,
        "finite": bool(torch.isfinite(embedding).all()),
        "distinct_envs": bool(num_envs == 1 or not torch.allclose(embedding[0], embedding[1]))}))
""")


def egl_probe(num_envs: int, device: str, timeout: float) -> dict:
    """:data:`EGL_PROBE` in a child process under ``timeout``; fails the test, naming the
    cause, when it hangs or breaks."""
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    start = time.perf_counter()
    status, output = run_with_timeout([sys.executable, "-c", EGL_PROBE, str(num_envs), device],
                                      timeout, env)
    if status is None:
        pytest.fail(f"EGL rendering with env.num_envs={num_envs} did not finish in {timeout:.0f}"
                    " s and was killed: the EGL renderers hung (mujoco issue #3444 reports EGL "
                    "renderers hanging in mjr_readPixels with 8 spawned envs on an H200). Use "
                    "fewer envs (env.num_envs=2) on this node. Its output:\n" + output[-3000:])
    if status != 0:
        pytest.fail(f"EGL rendering with env.num_envs={num_envs} failed (exit status {status}):"
                    "\n" + output[-3000:])
    line = next(line for line in output.splitlines() if line.startswith("EGL_PROBE "))
    result = json.loads(line.removeprefix("EGL_PROBE "))
    result["seconds"] = time.perf_counter() - start
    assert result["shape"] == [num_envs, 25, result["dim"]] and result["finite"], result
    assert result["distinct_envs"], f"the {num_envs} envs rendered the same frames: {result}"
    return result


@pytest.mark.cuda
@cuda
def test_egl_renders_eight_envs_on_the_gpu_without_hanging():
    """drawer-open rendered through EGL by 8 worker envs, embedded on CUDA, within
    :data:`EGL_TIMEOUT_S`; and EGL drew on the GPU, not in software."""
    result = egl_probe(8, "cuda", EGL_TIMEOUT_S)
    assert not any(name in result["renderer"].lower() for name in SOFTWARE_RENDERERS), (
        f"EGL rendered in software ({result['renderer']}): it found no NVIDIA EGL driver. "
        "Point __EGL_VENDOR_LIBRARY_FILENAMES at the driver's 10_nvidia.json (glvnd) and make "
        "sure libEGL_nvidia.so is on the library path.")


@pytest.mark.slow
def test_egl_probe_runs_two_envs_on_the_cpu():
    """The CPU side: the same probe with 2 envs (Mesa's software EGL here)."""
    result = egl_probe(2, "cpu", CPU_EGL_TIMEOUT_S)
    assert result["renderer"]


def test_a_hung_child_and_its_workers_are_killed_at_the_timeout(tmp_path):
    """The timeout ends a hung child and the workers it spawned (the EGL renderers' hang is in
    worker processes), and says it was killed."""
    pid_file = tmp_path / "worker.pid"
    hang = textwrap.dedent(f"""
        import subprocess, sys, time
        worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
        open({str(pid_file)!r}, "w").write(str(worker.pid))
        print("started", flush=True)
        time.sleep(600)
    """)
    start = time.perf_counter()
    status, output = run_with_timeout([sys.executable, "-c", hang], timeout=5)
    assert status is None and "started" in output
    assert time.perf_counter() - start < 60
    worker = int(pid_file.read_text())
    for _ in range(50):  # the killed worker is reaped by init shortly after
        if not _alive(worker):
            break
        time.sleep(0.1)
    assert not _alive(worker), "the hung child's worker survived the timeout"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    status = Path(f"/proc/{pid}/status")
    return not (status.exists() and "State:\tZ" in status.read_text())


def test_cuda_tests_skip_naming_why():
    """Without a GPU the ``cuda`` tests skip with a reason that says no CUDA device was found
    and where they run instead."""
    if HAS_CUDA:
        pytest.skip("CUDA is present: the cuda tests run")
    assert "no CUDA device" in NO_CUDA and "gpu_check.sh" in NO_CUDA


# ---- benchmarks/gpu_check.sh: its CPU path, its timeouts and budget, its sections on the CPU


@pytest.fixture
def gpu_rows(monkeypatch: pytest.MonkeyPatch):
    """``benchmarks/gpu_rows.py`` as a module (it imports the standard library alone)."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import gpu_rows

    return gpu_rows


def gpu_check(out: Path, *options: str, timeout: float = 240) -> tuple[int | None, str, dict]:
    """``gpu_check.sh OUT --no-install`` with this Python, the GPU hidden (so that a GPU
    machine checks the CPU path too): its exit status, output and JSON."""
    env = {**os.environ, "PYTHON": sys.executable, "CUDA_VISIBLE_DEVICES": ""}
    status, output = run_with_timeout(["bash", str(ROOT / "benchmarks" / "gpu_check.sh"),
                                       str(out), "--no-install", *options], timeout, env)
    assert (out / "gpu_check.json").exists(), output[-3000:]
    return status, output, json.loads((out / "gpu_check.json").read_text())


@pytest.mark.slow
def test_gpu_check_without_a_gpu_says_so_and_exits_0(tmp_path):
    """The CPU path: the install skipped (--no-install), the environment read, the cuda tests
    run (each skipped, naming why), the GPU sections written as skipped because no GPU was
    found; exit status 0, the JSON and the logs in the output folder."""
    status, output, check = gpu_check(tmp_path, "--sections", "cuda_tests,encoder")
    assert status == 0, output[-3000:]
    assert check["gpu"] is None and check["cuda"] is False and check["failed"] == []
    assert check["no_gpu"].startswith("no GPU found") and check["rows"] == []
    sections = {entry["name"]: entry for entry in check["sections"]}
    assert list(sections) == ["install", "environment", "cuda_tests", "encoder"]
    assert sections["install"]["status"] == "skipped"
    environment = check["environment"]
    assert environment["cuda_available"] is False and environment["versions"]["torchrl"]
    assert environment["paths"]["temporal_torchrl"] == str(ROOT / "temporal_torchrl")
    tests = sections["cuda_tests"]["info"]["tests"]
    assert sections["cuda_tests"]["status"] == "ok" and len(tests) >= 5
    assert {test["outcome"] for test in tests} == {"skipped"}
    assert all("no CUDA device" in test["message"] for test in tests)
    assert sections["encoder"]["status"] == "skipped"
    assert "no GPU found" in sections["encoder"]["reason"]
    assert {"gpu_check.log", "cuda_tests.log"} <= {path.name for path in tmp_path.iterdir()}
    assert "none failed" in (tmp_path / "gpu_check.log").read_text()


def test_gpu_check_section_that_hangs_is_killed_and_named(gpu_rows, tmp_path, monkeypatch):
    """A section past its timeout is killed and written as a timeout with the likely cause (the
    8-env loops: mujoco #3444); an environment that does not come up stops the sections after
    it; a spent budget leaves the rest not run; the exit status is 1 for a failure alone."""
    slow = gpu_rows.Section("environment", 0.5, needs_gpu=False, hang_hint=gpu_rows.EGL_HANG)
    monkeypatch.setattr(gpu_rows, "SECTIONS", (slow, gpu_rows.BY_NAME["encoder"]))
    check = gpu_rows.Check(out=tmp_path, python=sys.executable, budget_s=300,
                           started=time.time(), install=False, wheels=tmp_path,
                           target=tmp_path, cpu_rows=False,
                           selected=("environment", "encoder"))
    assert check.run() == 1
    written = json.loads((tmp_path / "gpu_check.json").read_text())
    environment, encoder = written["sections"]
    assert environment["status"] == "timeout" and "#3444" in environment["reason"]
    assert "killed" in environment["reason"]
    assert encoder["status"] == "not run" and "environment section failed" in encoder["reason"]
    assert written["failed"] == ["environment"] and written["not_run"] == ["encoder"]

    monkeypatch.setattr(gpu_rows, "SECTIONS", (gpu_rows.BY_NAME["encoder"],))
    spent = gpu_rows.Check(out=tmp_path, python=sys.executable, budget_s=300,
                           started=time.time() - 295, install=False, wheels=tmp_path,
                           target=tmp_path, cpu_rows=False, selected=("encoder",))
    assert spent.run() == 0  # nothing found wrong; the JSON and the summary say what did not run
    written = json.loads((tmp_path / "gpu_check.json").read_text())
    (entry,) = written["sections"]
    assert entry["status"] == "not run" and "budget was spent" in entry["reason"]
    assert written["failed"] == [] and written["not_run"] == ["encoder"]


def test_gpu_check_install_names_a_missing_wheelhouse(gpu_rows, tmp_path, monkeypatch):
    """Without wheels the install section fails, saying how to make them."""
    monkeypatch.setattr(gpu_rows, "SECTIONS", (gpu_rows.BY_NAME["install"],))
    check = gpu_rows.Check(out=tmp_path, python=sys.executable, budget_s=300,
                           started=time.time(), install=True, wheels=tmp_path / "none",
                           target=tmp_path / "site", cpu_rows=False, selected=("install",))
    assert check.run() == 1
    (entry,) = json.loads((tmp_path / "gpu_check.json").read_text())["sections"]
    assert entry["status"] == "failed" and "device_wheels.sh" in entry["reason"]


@pytest.mark.slow
def test_gpu_check_sections_run_on_the_cpu_at_smoke_sizes(tmp_path):
    """``--cpu-rows``: GPU sections' code runs on the CPU at smoke sizes and gives its rows, so
    that the first GPU node does not find their bugs: the encoder's, the bound's and the
    loop's (the other sections share theirs; all of them take about 7 minutes on 2 cores)."""
    sections = ("encoder", "sac_update", "loop_shipped_1")
    status, output, check = gpu_check(tmp_path, "--cpu-rows", "--budget", "900",
                                      "--sections", ",".join(sections), timeout=960)
    assert status == 0, output[-3000:]
    assert check["failed"] == [] and check["sizes"].startswith("smoke"), check["sections"]
    measured = [entry for entry in check["sections"] if entry["rows"]]
    assert [entry["name"] for entry in measured] == list(sections)
    for row in check["rows"]:
        assert set(row) == {"section", "measure", "project", "reference", "reference is",
                            "ratio"}, row
        assert isinstance(row["project"], float) and row["project"] > 0, row
