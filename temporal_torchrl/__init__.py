"""Temporal vision-language reward shaping for reinforcement learning, on TorchRL.

Importing the package picks MuJoCo's headless OpenGL backend when the user has not:
with no display and ``MUJOCO_GL`` unset, EGL is used (osmesa crashes under TorchRL).
This must happen before the first ``import mujoco``, hence here.
"""

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"
