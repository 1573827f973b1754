"""Zero-shot value-order correlation of image/text encoders on the six held-out evaluation tasks
(what it measures: :mod:`temporal_torchrl.reward_quality.encoder_evaluation`).

    python recipes/evaluate_encoder.py                      # shipped small encoder vs baselines
    python recipes/evaluate_encoder.py --liv-checkpoint model.pt   # adds real LIV
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

import temporal_torchrl  # noqa: F401  (chooses the GL backend before mujoco loads)
from temporal_torchrl.encoders.small import SmallEncoder
from temporal_torchrl.reward_quality.encoder_evaluation import (
    collect_evaluation_videos,
    default_encoders,
    evaluate_encoders,
    markdown_table,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", default=None,
                        help="small-encoder checkpoint (default: the shipped weights)")
    parser.add_argument("--liv-checkpoint", default=None, help="LIV's model.pt, if you have it")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per task")
    parser.add_argument("--large-episodes", type=int, default=2,
                        help="episodes per task for the RN50 rows")
    parser.add_argument("--large-stride", type=int, default=4,
                        help="every n-th frame for the RN50 rows (RN50 is slow on a CPU)")
    parser.add_argument("--no-random-liv", action="store_true", help="skip the random RN50 row")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    for flag, path in (("--checkpoint", args.checkpoint),
                       ("--liv-checkpoint", args.liv_checkpoint)):
        if path is not None and not Path(path).is_file():
            parser.error(f"{flag} {path!r} is not a file: pass the path of a weights file "
                         "(LIV's model.pt from https://huggingface.co/jasonyma/LIV for "
                         "--liv-checkpoint), or leave the flag out.")
    torch.set_num_threads(args.threads)
    config = SmallEncoder.from_pretrained(args.checkpoint).config()
    small_videos = collect_evaluation_videos(int(config["image_size"]), args.episodes, args.seed)
    need_large = not args.no_random_liv or args.liv_checkpoint
    large_videos = collect_evaluation_videos(224, args.large_episodes, args.seed) \
        if need_large else {}
    rows = evaluate_encoders(default_encoders(args.checkpoint, args.liv_checkpoint, args.seed,
                                              not args.no_random_liv),
                             small_videos, large_videos, args.large_stride)
    print(markdown_table(rows))


if __name__ == "__main__":
    main()
