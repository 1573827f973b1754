"""EmbeddingTransform throughput against the raw LIV forward on the same batch.

Both sides include LIV's preprocessing (uint8 [N, 224, 224, 3] frames -> normalised NCHW), so the
ratio is the transform's own overhead (tensordict handling, batch flattening, the copy out of
inference mode). The weights are random (written by ``save_random_liv_checkpoint``, so nothing is
downloaded); speed does not depend on their values.

CPU rows: batch 1 (one env step) and 32 (a batched env or replay batch), float32; target ratio
>= 0.95. GPU rows (when CUDA is available): batch 256 in float32, and with bf16 autocast and
channels-last, frames sent from the CPU as in an env (host-to-device copy included) or made on
the GPU. ``--smoke``: batches 1 and 2 on the CPU, 4 on the GPU.

    python benchmarks/bench_encoders.py [--quick | --smoke] [--json out.json]
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Sequence
from pathlib import Path

import torch
from _common import parse_args, rate, report
from tensordict import TensorDict

from temporal_torchrl.encoders import LIVEncoder, save_random_liv_checkpoint
from temporal_torchrl.transforms import EmbeddingTransform


def _compare(encoder: LIVEncoder, batch: int, device: torch.device, autocast_dtype,
             frames_device: torch.device, min_seconds: float, rounds: int) -> dict:
    """Images/s of the transform's env path and of the raw forward, best of interleaved rounds."""
    frames = torch.randint(0, 256, (batch, 224, 224, 3), dtype=torch.uint8,
                           device=frames_device)
    transform = EmbeddingTransform(encoder, device=device, autocast_dtype=autocast_dtype)
    sync = torch.cuda.synchronize if device.type == "cuda" else None

    def raw() -> torch.Tensor:
        autocast = (torch.autocast(device.type, dtype=autocast_dtype) if autocast_dtype
                    else contextlib.nullcontext())
        with torch.inference_mode(), autocast:
            images = encoder.preprocess(frames.to(device, non_blocking=True))
            return encoder.model.encode_image(images).float().to(frames_device)

    def transformed() -> TensorDict:
        return transform._call(TensorDict({"pixels": frames}, batch_size=[batch],
                                          device=frames_device))

    # Interleaved rounds, best of each: other processes on a shared machine slow both alike.
    raw_rates, transform_rates = [], []
    for round_index in range(rounds):
        warmup = 1 if round_index == 0 else 0
        raw_rates.append(rate(raw, batch, min_seconds, warmup, sync))
        transform_rates.append(rate(transformed, batch, min_seconds, warmup, sync))
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    precision = f"{autocast_dtype}".removeprefix("torch.") if autocast_dtype else "float32"
    if encoder.channels_last:
        precision += " + channels_last"
    return {
        "device": name,
        "batch": batch,
        "precision": precision,
        "frames from": str(frames_device),
        "transform img/s": max(transform_rates),
        "raw forward img/s": max(raw_rates),
        "ratio": max(transform_rates) / max(raw_rates),
    }


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    min_seconds = 0.0 if args.quick or args.smoke else 3.0
    rounds = 1 if args.quick or args.smoke else 2
    cpu_batches, gpu_batch = ((1, 2), 4) if args.smoke else ((1, 32), 256)
    rows = []
    with tempfile.TemporaryDirectory() as directory:
        checkpoint = Path(directory) / "model.pt"
        save_random_liv_checkpoint(checkpoint)
        cpu = torch.device("cpu")
        encoder = LIVEncoder(checkpoint)
        for batch in cpu_batches:
            rows.append(_compare(encoder, batch, cpu, None, cpu, min_seconds, rounds))
        if torch.cuda.is_available():
            gpu = torch.device("cuda")
            encoder = LIVEncoder(checkpoint).to(gpu)
            rows.append(_compare(encoder, gpu_batch, gpu, None, cpu, min_seconds, rounds))
            encoder = LIVEncoder(checkpoint, channels_last=True).to(gpu)
            for frames_device in (cpu, gpu):
                rows.append(_compare(encoder, gpu_batch, gpu, torch.bfloat16, frames_device,
                                     min_seconds, rounds))
    report("EmbeddingTransform (LIV RN50, random weights) vs raw forward", rows, args.json)


if __name__ == "__main__":
    main()
