"""Throughput of the small Metaworld encoder vs LIV's RN50 image tower (random weights).

Rows: images/s of ``metaworld_small`` at its input size (64x64 frames, no resize) and from
224x224 frames (resized by the encoder), batch 1 and 32, next to the random-weight LIV RN50
(the reference: LIV's architecture, 224x224 frames) measured in the same run.
``--smoke``: batches 1 and 2.
Run: ``python benchmarks/bench_small_encoder.py [--quick | --smoke] [--json out.json]``.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import torch
from _common import parse_args, rate, report

from temporal_torchrl.encoders import load_encoder, save_random_liv_checkpoint


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(__doc__.split("\n")[0], argv)
    seconds = 0.05 if args.smoke else 0.5 if args.quick else 2.0
    batches = (1, 2) if args.smoke else (1, 32)
    small = load_encoder("metaworld_small")
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "random_liv.pt"
        save_random_liv_checkpoint(path)
        liv = load_encoder("liv", checkpoint=str(path))

    def frames(batch: int, size: int) -> torch.Tensor:
        return torch.randint(0, 256, (batch, size, size, 3), dtype=torch.uint8)

    rows = []
    for batch in batches:
        liv_frames = frames(batch, 224)
        # RN50 is slow on a CPU: time it briefly, once per batch size.
        reference = rate(lambda f=liv_frames: liv.embed_images(f), batch,
                         min_seconds=seconds, warmup_calls=1)
        for size in (small.image_size, 224):
            small_frames = frames(batch, size)
            figure = rate(lambda f=small_frames: small.embed_images(f), batch,
                          min_seconds=seconds)
            rows.append({"batch": batch, "small input": f"{size}x{size}",
                         "metaworld_small img/s": figure,
                         "LIV RN50 (random) img/s at 224": reference,
                         "ratio": figure / reference})
    text = rate(lambda: (small.clear_text_cache(), small.embed_text(["open a drawer"])), 1,
                min_seconds=seconds)
    rows.append({"batch": 1, "small input": "text (uncached)", "metaworld_small img/s": text,
                 "LIV RN50 (random) img/s at 224": float("nan"), "ratio": float("nan")})
    report("Small encoder vs LIV RN50 (images or prompts per second)", rows, args.json)


if __name__ == "__main__":
    main()
