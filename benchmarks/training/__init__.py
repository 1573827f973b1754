"""The sections of ``benchmarks/bench_training.py``, one module each, named for what it runs.

- :mod:`.sac_update`: the SAC update alone (section ``sac_update``, or ``sac``);
- :mod:`.head_update`: the reward-head update alone (``head_update``, or ``heads``);
- :mod:`.training_step`: the recipe's training step (``training_step``, or ``step``);
- :mod:`.default_loop`: the default loop against its bound, compiled and another revision's
  (``default_loop``, or ``loop``);
- :mod:`.d_sequence`: d_sequence against D3 (``d_sequence``, or ``sequence``);
- :mod:`.loop_grid`: the whole loop by encoder, envs and compilation (``loop_grid``, or
  ``grid``);
- :mod:`.plain_loop`: the recipe without a VLM reward against a plain TorchRL SAC loop
  (``plain_loop``, or ``reference``);
- :mod:`.replay`: replay sampling and memory (``replay``).

:mod:`.common` builds the recipe's parts and runs its loop for them, :mod:`.bounds` holds the
compute bound, the matmuls-alone replay and the row builders they share.

Importing the package puts the measured tree first on ``sys.path``: this checkout, or the tree
that ``TEMPORAL_TORCHRL_TREE`` names (the default loop of another revision, which
``bench_training.py`` measures by running itself in a fresh process with that variable set).
It has to come before the first import of ``temporal_torchrl``, ``_common``'s included.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The tree whose recipe (``recipes/sac_temporal.py``) and package are measured.
TREE = Path(os.environ.get("TEMPORAL_TORCHRL_TREE", Path(__file__).resolve().parents[2]))
RECIPES = TREE / "recipes"
sys.path[:0] = [str(RECIPES), str(TREE)]
