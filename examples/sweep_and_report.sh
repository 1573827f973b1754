#!/usr/bin/env bash
# A sweep (two seeds of the default configuration, one run directory each), then its report.
#
#   bash examples/sweep_and_report.sh                      # 2 runs x the default 5 episodes
#   bash examples/sweep_and_report.sh train.episodes=20    # any recipe overrides, for every run
#   LAUNCHER=basic bash examples/sweep_and_report.sh ...   # one run after the other, in-process
#
# SWEEP (default sweeps/example) and OUT (default reports/example) name the directories;
# LAUNCHER is joblib (local processes) by default, submitit_slurm for a Slurm cluster.
# Launching it again resumes the runs, and runs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python}
SWEEP=${SWEEP:-sweeps/example}
OUT=${OUT:-reports/example}

"$PYTHON" recipes/sac_temporal.py -m hydra/launcher="${LAUNCHER:-joblib}" \
    hydra.sweep.dir="$SWEEP" env.seed=0,1 "$@"
"$PYTHON" recipes/report.py "$SWEEP" --out "$OUT"
