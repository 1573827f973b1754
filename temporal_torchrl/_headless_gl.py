"""Headless OpenGL for MuJoCo: EGL when there is no display, whatever was imported first.

MuJoCo reads ``MUJOCO_GL`` once, when it is first imported, and ``import torchrl.envs`` already
imports it: a script that imports torchrl before temporal_torchrl would get GLFW, which cannot open
a context without a display. MuJoCo's renderer looks its context class up at construction time,
so switching that class works as long as nothing has rendered yet.
"""

from __future__ import annotations

import os
import sys

#: Rasteriser threads for Mesa's software renderer (llvmpipe) when the user has not chosen.
#: llvmpipe starts one per core; on a 2-core CPU, 4 overlap binning and rasterising and render
#: Metaworld frames about 15% faster (84 -> 97 frames/s at 224x224, raw mujoco.Renderer too);
#: 8 were no faster. GPU drivers ignore the variable.
SOFTWARE_RASTERISER_THREADS = 4


def choose_headless_backend() -> None:
    """Set ``MUJOCO_GL=egl`` when it is unset and there is no display (osmesa crashes here)."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("LP_NUM_THREADS", str(SOFTWARE_RASTERISER_THREADS))


def match_mujoco_backend() -> None:
    """Make an already imported MuJoCo use EGL when ``MUJOCO_GL=egl`` was set after its import."""
    if "mujoco" not in sys.modules or os.environ.get("MUJOCO_GL", "").lower() != "egl":
        return
    from mujoco import gl_context

    chosen = getattr(gl_context, "GLContext", None)
    if chosen is not None and chosen.__module__ != "mujoco.egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        from mujoco.egl import GLContext

        gl_context.GLContext = GLContext
