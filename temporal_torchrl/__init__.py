"""Temporal vision-language reward shaping for reinforcement learning, on TorchRL.

Importing the package picks MuJoCo's headless OpenGL backend when the user has not: with no
display and ``MUJOCO_GL`` unset, EGL is used (osmesa crashes under TorchRL, GLFW needs a display).
MuJoCo chooses its backend when it is first imported, and importing ``torchrl.objectives`` or
``torchrl.collectors`` already imports it; so if MuJoCo came first, its context class is switched
to EGL here, which works as long as nothing has rendered yet.
"""

import os
import sys


def _use_headless_egl() -> None:
    if "MUJOCO_GL" in os.environ or os.environ.get("DISPLAY"):
        return
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    if "mujoco" in sys.modules:
        from mujoco import egl, gl_context

        gl_context.GLContext = egl.GLContext


_use_headless_egl()

__version__ = "0.1.0"
