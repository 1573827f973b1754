"""Compute bounds, matmuls alone, alternating timings and the rows that show them.

Compute bound: the FLOPs torch's profiler counts (``with_flops``: the matrix products) divided
by the machine's fp32 GEMM rate (a 2048^3 matmul, measured in the same run). Matmuls alone: the
matrix products one call dispatches, forward and backward, recorded and replayed by themselves
at their shapes and strides; their share of the time bounds what any speed-up that keeps the
same matmul kernels (compile included) can give.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable

import torch
from _common import seconds_per_call
from torch.profiler import ProfilerActivity, profile
from torch.utils._python_dispatch import TorchDispatchMode

#: The matmul whose rate is the machine's fp32 GEMM rate: 2048^3, and its FLOPs.
GEMM_SIZE = 2048
GEMM_FLOPS = 2 * GEMM_SIZE ** 3


def gemm() -> Callable[[], torch.Tensor]:
    """One call of the reference matmul (``GEMM_FLOPS``), on operands made once."""
    a, b = torch.randn(GEMM_SIZE, GEMM_SIZE), torch.randn(GEMM_SIZE, GEMM_SIZE)
    return lambda: a @ b


def gemm_flops_per_second(min_seconds: float = 2.0) -> float:
    """The machine's fp32 GEMM rate now, timed over ``min_seconds``."""
    return GEMM_FLOPS / seconds_per_call(gemm(), min_seconds=min_seconds)


def counted_flops(fn: Callable[[], object]) -> float:
    """The FLOPs of one call of ``fn`` (after one warm-up call), as torch's profiler counts."""
    fn()
    with profile(activities=[ProfilerActivity.CPU], with_flops=True) as profiler:
        fn()
    return sum(event.flops for event in profiler.key_averages())


def bound_row(measure: str, seconds: float, flops: float, peak: float) -> dict:
    """``seconds`` a call against ``flops`` at the GEMM rate ``peak``: the ratio is the
    fraction of the bound reached."""
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
    its own round (the machine's load moves both): the medians, and the fraction's spread."""
    fractions = [flops / peak / time for peak, time in zip(peaks, seconds, strict=True)]
    peak = statistics.median(peaks)
    return {**bound_row(measure, statistics.median(seconds), flops, peak),
            "reference is": f"compute bound: {flops / 1e9:.2f} GFLOP / {peak / 1e9:.0f} GFLOP/s "
                            f"GEMM, each round's (fraction {spread(fractions)})",
            "ratio": statistics.median(fractions)}


def alternating_seconds(calls: dict[str, Callable[[], object]], rounds: int,
                        min_seconds: float, warmup_calls: int = 3) -> dict[str, list[float]]:
    """Seconds per call of each of ``calls`` in ``rounds`` rounds, the calls taking turns within
    each round, so that the machine's load changes reach them all alike."""
    times: dict[str, list[float]] = {name: [] for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            times[name].append(seconds_per_call(call, min_seconds=min_seconds,
                                                warmup_calls=warmup_calls))
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


def matmuls_alone(fn: Callable[[], object]) -> Callable[[], None]:
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
