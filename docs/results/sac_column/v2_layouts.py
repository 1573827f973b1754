"""The layouts a task's seeds give in Metaworld v3 (ours) and in v2 (the thesis release's).

Both versions seed numpy's global generator with the env's seed in the goal-hidden constructor and
draw the layout vector uniformly from the task's ``_random_reset_space``; v2 keeps the first draw,
v3 the second (its constructor draws once more before the reset that freezes the layout). The
script checks the second draw against the layout v3 actually froze, so the v2 column is the same
computation one draw earlier, not a guess.

    python docs/results/sac_column/v2_layouts.py drawer-open --seeds 0 1 2 3
"""

from __future__ import annotations

import argparse

import metaworld.env_dict
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task", help="a Metaworld task id without the version, e.g. drawer-open")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    args = parser.parse_args()

    make = metaworld.env_dict.ALL_V3_ENVIRONMENTS_GOAL_HIDDEN[f"{args.task}-v3-goal-hidden"]
    print(f"{args.task}: layout vector (randomised coordinates only), v3 against v2")
    print("| seed | v3 (ours) | v2 (thesis release) | largest difference |")
    print("|---|---|---|---|")
    for seed in args.seeds:
        env = make(seed=seed)
        space = env._random_reset_space
        generator = np.random.RandomState(seed)
        first, second = (generator.uniform(space.low, space.high, size=space.low.size)
                         for _ in range(2))
        if not np.allclose(second, env._last_rand_vec):
            raise SystemExit(f"seed {seed}: v3's layout is not the second draw after seeding; "
                             "this metaworld version draws differently, the v2 column would be "
                             "wrong.")
        varied = space.high > space.low
        difference = np.abs(first - second)[varied].max()
        print(f"| {seed} | {np.round(second[varied], 3).tolist()} | "
              f"{np.round(first[varied], 3).tolist()} | {difference:.3f} |")
        env.close()


if __name__ == "__main__":
    main()
