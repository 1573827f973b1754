"""The GPU node check's sections (``benchmarks/gpu_rows.py``): each one's own code, run by the
check in a child process of its own, which imports torch and the project.

    python benchmarks/gpu_sections.py NAME --json PATH [--device cuda] [--size full|smoke]

It writes ``{"rows": [...], "info": {...}}`` to ``PATH``: the rows the check reports (the
project's figure beside its reference) and what the section found out. ``--size smoke`` runs it
at the sizes ``gpu_rows.py --cpu-rows`` uses on a CPU, where its figures mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

#: The carried packages whose versions and import paths the environment section writes.
PACKAGES = ("torch", "torchvision", "numpy", "torchrl", "tensordict", "mujoco", "metaworld",
            "gymnasium", "open_clip_torch", "hydra-core", "omegaconf", "scipy", "timm")


def _setup_paths() -> None:
    """The checkout's recipes and package, and benchmarks/training's helpers, importable."""
    import training  # noqa: F401  (puts the measured tree first on sys.path)


def _sync(device: str) -> Callable[[], None] | None:
    import torch

    return torch.cuda.synchronize if device.startswith("cuda") else None


def _seconds(fn: Callable[[], object], device: str, smoke: bool) -> float:
    from _common import seconds_per_call

    # GPU timings are steady: one second a measurement keeps the check inside its budget
    return seconds_per_call(fn, min_seconds=0.05 if smoke else 1.0,
                            warmup_calls=1 if smoke else 5, sync=_sync(device))


def gemm_rate(device: str, smoke: bool) -> float:
    """The device's fp32 GEMM rate now (FLOP/s): the compute bound's denominator, the same
    precision as the updates (torch's default: no TF32)."""
    import torch

    size = 512 if smoke else (8192 if device.startswith("cuda") else 2048)
    a, b = (torch.randn(size, size, device=device) for _ in range(2))
    return 2 * size ** 3 / _seconds(lambda: a @ b, device, smoke)


def _budget(device: str, smoke: bool):
    """benchmarks/training's budget, everything on ``device``."""
    from dataclasses import replace

    from training.common import FULL, SMOKE

    budget = SMOKE if smoke else FULL
    return replace(budget, overrides=(*budget.overrides, f"train.device={device}"))


def _device_name(device: str) -> str:
    import torch

    return torch.cuda.get_device_name(device) if device.startswith("cuda") else "CPU"


def section_environment(device: str, smoke: bool, tmp: Path) -> tuple[list[dict], dict]:
    import importlib
    import importlib.metadata as metadata
    import platform

    import torch

    from temporal_torchrl.machine import machine_description

    info: dict = {"python": platform.python_version(), "torch": torch.__version__,
                  "torch_cuda": torch.version.cuda, "cuda_available": torch.cuda.is_available(),
                  "machine": machine_description(), "versions": {}, "paths": {}}
    for name in PACKAGES:
        try:
            info["versions"][name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            info["versions"][name] = None
    for module in ("torch", "torchrl", "tensordict", "mujoco", "metaworld", "temporal_torchrl"):
        try:
            info["paths"][module] = str(Path(importlib.import_module(module).__file__).parent)
        except ImportError as error:
            info["paths"][module] = f"not importable: {error}"
    try:  # only the prioritized replay's segment trees use it; the project does not
        importlib.import_module("torchrl._torchrl")
        info["torchrl_extension"] = "loaded"
    except ImportError as error:
        info["torchrl_extension"] = f"not loaded (unused here): {str(error)[:200]}"
    if info["cuda_available"]:
        properties = torch.cuda.get_device_properties(0)
        info.update(gpu=torch.cuda.get_device_name(0), gpu_count=torch.cuda.device_count(),
                    capability=".".join(map(str, torch.cuda.get_device_capability(0))),
                    gpu_memory_gib=round(properties.total_memory / 2**30, 1),
                    bf16=torch.cuda.is_bf16_supported())
    info["env"] = {key: os.environ.get(key) for key in (
        "MUJOCO_GL", "PYOPENGL_PLATFORM", "__EGL_VENDOR_LIBRARY_FILENAMES",
        "CUDA_VISIBLE_DEVICES", "MUJOCO_EGL_DEVICE_ID")}
    return [], info


def section_egl_context(device: str, smoke: bool, tmp: Path) -> tuple[list[dict], dict]:
    from mujoco.egl import GLContext
    from OpenGL import GL

    context = GLContext(64, 64)
    context.make_current()
    try:
        info = {key: GL.glGetString(getattr(GL, f"GL_{key.upper()}")).decode()
                for key in ("vendor", "renderer", "version")}
    finally:
        context.free()
    software = ("llvmpipe", "softpipe", "swrast", "software")
    info["software"] = any(name in info["renderer"].lower() for name in software)
    return [], info


def section_encoder(device: str, smoke: bool, tmp: Path) -> tuple[list[dict], dict]:
    """The embedding transform's env path (frames from the CPU, as envs hand them over) against
    the raw model forward, at each batch and precision (``bench_encoders``'s comparison)."""
    import torch
    from bench_encoders import _compare

    from temporal_torchrl.encoders import LIVEncoder, save_random_liv_checkpoint

    checkpoint = tmp / "liv.pt"
    save_random_liv_checkpoint(checkpoint)
    where, cpu = torch.device(device), torch.device("cpu")
    precisions: list[tuple[torch.dtype | None, bool]] = [(None, False)]
    if where.type == "cuda":
        precisions.append((torch.bfloat16, True))
    rows = []
    for autocast_dtype, channels_last in precisions:
        encoder = LIVEncoder(checkpoint, channels_last=channels_last).to(where)
        for batch in ((1, 2) if smoke else (1, 32, 256)):
            row = _compare(encoder, batch, where, autocast_dtype, cpu,
                           0.0 if smoke else 1.0, 1)
            rows.append({
                "measure": f"LIV-shaped RN50, 224 px, batch {batch}, {row['precision']}, "
                           f"frames from the CPU, {row['device']} (images/s)",
                "project": row["transform img/s"], "reference": row["raw forward img/s"],
                "reference is": "the raw model forward, same preprocessing",
                "ratio": row["ratio"]})
    return rows, {}


def section_training_step(device: str, smoke: bool, tmp: Path) -> tuple[list[dict], dict]:
    from training.bounds import bound_row, counted_flops
    from training.training_step import training_step

    step = training_step(False, tmp, _budget(device, smoke))
    flops = counted_flops(step)
    seconds = _seconds(step, device, smoke)
    peak = gemm_rate(device, smoke)
    return [bound_row(f"training step, stage 2, D=1024, eager, {_device_name(device)} (ms)",
                      seconds, flops, peak)], {"gemm_tflops": round(peak / 1e12, 2)}


def section_sac_update(device: str, smoke: bool, tmp: Path) -> tuple[list[dict], dict]:
    from training.bounds import bound_row, counted_flops
    from training.common import training_setup
    from training.sac_update import cycling

    setup = training_setup(tmp, _budget(device, smoke), 256)
    update = cycling(setup["update_sac"], [setup["buffer"].sample() for _ in range(8)])
    flops = counted_flops(update)
    seconds = _seconds(update, device, smoke)
    peak = gemm_rate(device, smoke)
    return [bound_row(f"SAC update, batch {setup['cfg'].sac.batch_size}, eager, "
                      f"{_device_name(device)} (ms)", seconds, flops, peak)], {
        "gemm_tflops": round(peak / 1e12, 2)}


def section_sac_update_cudagraphs(device: str, smoke: bool, tmp: Path
                                  ) -> tuple[list[dict], dict]:
    """The SAC update as the GPU recipe runs it (compile.enabled, compile.cudagraphs) against
    the eager one, on the same batches; compile.cudagraphs is CUDA's alone, so the CPU check
    compiles without it."""
    from training.common import training_setup
    from training.sac_update import cycling

    budget = _budget(device, smoke)
    eager = training_setup(tmp, budget, 256)
    batches = [eager["buffer"].sample() for _ in range(8)]
    graphs = str(device.startswith("cuda")).lower()
    compiled = cycling(training_setup(tmp, budget, 256, "compile.enabled=true",
                                      f"compile.cudagraphs={graphs}")["update_sac"], batches)
    start = time.perf_counter()
    for _ in range(8):  # compilation, then CudaGraphModule's warm-up calls and its capture
        compiled()
    compile_seconds = time.perf_counter() - start
    eager_seconds = _seconds(cycling(eager["update_sac"], batches), device, smoke)
    compiled_seconds = _seconds(compiled, device, smoke)
    what = "compiled + CUDA graph" if graphs == "true" else "compiled"
    return [{"measure": f"SAC update, {what} (compile {compile_seconds:.0f} s), "
                        f"{_device_name(device)} (ms)",
             "project": 1000 * compiled_seconds, "reference": 1000 * eager_seconds,
             "reference is": "the eager update, same batches",
             "ratio": eager_seconds / compiled_seconds}], {}


#: The loops' encoders: benchmarks/training/loop_grid's names and overrides, and the episode
#: length (full, smoke); rates are timed over the 3rd and 4th rounds of episodes.
LOOP_LENGTHS = {"metaworld_small": (30, 4), "liv": (30, 2)}


def _loop(encoder: str, num_envs: int, device: str, smoke: bool, tmp: Path
          ) -> tuple[list[dict], dict]:
    from training.common import steady_steps_per_second
    from training.loop_grid import ENCODERS

    from temporal_torchrl.encoders import save_random_liv_checkpoint

    name, overrides = ENCODERS[encoder]
    if encoder == "liv":
        name = "LIV-shaped RN50, 224 px"
        checkpoint = tmp / "liv.pt"
        save_random_liv_checkpoint(checkpoint)
        overrides = (*overrides, f"encoder.checkpoint={checkpoint}")
    if smoke:
        num_envs = min(num_envs, 2)  # 8 spawned workers on a small CPU: minutes, no check
    length = LOOP_LENGTHS[encoder][1 if smoke else 0]
    rate = steady_steps_per_second([*overrides, f"encoder.device={device}"], num_envs, length,
                                   tmp, _budget(device, smoke))
    return [{"measure": f"whole loop, {name}, {num_envs} env(s), eager, everything on "
                        f"{_device_name(device)} (env steps/s)",
             "project": rate, "reference": float("nan"), "reference is": "-",
             "ratio": float("nan")}], {"episode_length": length, "num_envs": num_envs}


CHILD_SECTIONS: dict[str, Callable[[str, bool, Path], tuple[list[dict], dict]]] = {
    "environment": section_environment,
    "egl_context": section_egl_context,
    "encoder": section_encoder,
    "training_step": section_training_step,
    "sac_update": section_sac_update,
    "loop_shipped_1": lambda device, smoke, tmp: _loop("metaworld_small", 1, device, smoke, tmp),
    "loop_shipped_8": lambda device, smoke, tmp: _loop("metaworld_small", 8, device, smoke, tmp),
    "loop_liv_1": lambda device, smoke, tmp: _loop("liv", 1, device, smoke, tmp),
    "loop_liv_8": lambda device, smoke, tmp: _loop("liv", 8, device, smoke, tmp),
    "sac_update_cudagraphs": section_sac_update_cudagraphs,
}


def run_section(name: str, device: str, size: str, json_path: Path) -> None:
    """One section in this process; its rows and information to ``json_path``."""
    if name != "egl_context":  # that one imports mujoco and OpenGL alone
        _setup_paths()
    with tempfile.TemporaryDirectory(prefix=f"gpu_rows_{name}_") as tmp:
        rows, info = CHILD_SECTIONS[name](device, size == "smoke", Path(tmp))
    json_path.write_text(json.dumps({"rows": rows, "info": info}, default=str))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("section", choices=sorted(CHILD_SECTIONS))
    parser.add_argument("--json", type=Path, required=True, help="where the result goes")
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--size", choices=("full", "smoke"), default="full")
    args = parser.parse_args(argv)
    run_section(args.section, args.device, args.size, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
