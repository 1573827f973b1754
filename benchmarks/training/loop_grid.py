"""Section ``loop_grid`` (``grid``): the whole loop by encoder, envs and compilation.

The whole recipe for the state encoder (D = 1024), the shipped encoder at 64 px and a
random-weight LIV at 224 px (``--smoke``: the state encoder alone); ``env.num_envs`` 1, 2 and 4
(``--quick``: 1 and 2; ``--smoke``: 1), eager and compiled; each against the loop of one env,
eager, of the same encoder; with CUDA also LIV with 16 envs, everything on the GPU, compiled.
"""

from __future__ import annotations

from pathlib import Path

import torch

from temporal_torchrl.encoders import save_random_liv_checkpoint
from training.common import Budget, steady_steps_per_second

#: The grid's encoders by ``encoder.name``: their rows' name and their overrides.
ENCODERS = {
    "state": ("state encoder, D=1024", ("encoder.name=state", "+encoder.options.dim=1024")),
    "metaworld_small": ("shipped encoder, 64 px",
                        ("encoder.name=metaworld_small", "env.image_size=64")),
    "liv": ("random LIV, 224 px", ("encoder.name=liv", "env.image_size=224")),
}


def grid_rows(tmp: Path, budget: Budget, skip_liv: bool, mode: str | None) -> list[dict]:
    """The loop of each of ``budget.grid_encoders`` (LIV left out with ``skip_liv``) at each
    of ``budget.num_envs``, eager and compiled (``mode``), against its one env, eager."""
    rows = []
    for encoder in budget.grid_encoders:
        liv = encoder == "liv"
        if skip_liv and liv:
            continue
        name, overrides = ENCODERS[encoder]
        if liv:
            checkpoint = tmp / "liv.pt"
            save_random_liv_checkpoint(checkpoint)
            overrides = (*overrides, f"encoder.checkpoint={checkpoint}")
        length = budget.liv_episode_length if liv else budget.episode_length
        one_env = None
        for compiled in (False, True):
            for num_envs in budget.num_envs:
                rate = steady_steps_per_second(
                    [*overrides, f"compile.enabled={str(compiled).lower()}",
                     f"compile.mode={mode or 'null'}"], num_envs, length, tmp, budget)
                one_env = rate if one_env is None else one_env
                print(f"loop: {name}, {num_envs} envs, compiled={compiled}: {rate:.1f}/s",
                      flush=True)
                rows.append({"measure": f"whole loop, {name}, {num_envs} env(s), "
                                        f"{'compiled' if compiled else 'eager'} (env steps/s)",
                             "project": rate, "reference": one_env,
                             "reference is": "one env, eager", "ratio": rate / one_env})
        if torch.cuda.is_available() and liv and budget.gpu_rows:
            # Everything on the GPU, 16 rendering workers, compiled updates.
            rate = steady_steps_per_second(
                [*overrides, "train.device=cuda", "compile.enabled=true",
                 f"compile.mode={mode or 'null'}"], 16, length, tmp, budget)
            rows.append({"measure": f"whole loop, {name}, 16 envs, compiled, "
                                    f"{torch.cuda.get_device_name(0)} (env steps/s)",
                         "project": rate, "reference": one_env,
                         "reference is": "one env, eager, CPU", "ratio": rate / one_env})
    return rows
