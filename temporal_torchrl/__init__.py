"""Temporal vision-language reward shaping for reinforcement learning, on TorchRL.

Importing the package picks MuJoCo's headless OpenGL backend when the user has not: with no
display and ``MUJOCO_GL`` unset, EGL is used, also when torchrl (which imports MuJoCo) was
imported first. See :mod:`temporal_torchrl._headless_gl`.
"""

from temporal_torchrl._headless_gl import choose_headless_backend, match_mujoco_backend

choose_headless_backend()
match_mujoco_backend()

__version__ = "0.1.0"
