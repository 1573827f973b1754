"""Render upright camera frames of a MuJoCo-based env as a TorchRL transform.

The frames o_t are what the VLM image encoder embeds, s_t = phi_I(o_t) (thesis chapter 5).
"""

from __future__ import annotations

import atexit
import os
import weakref

import mujoco
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Bounded, Composite
from torchrl.envs import EnvBase
from torchrl.envs.transforms import Transform

from temporal_torchrl import defaults
from temporal_torchrl._headless_gl import match_mujoco_backend


class RenderTransform(Transform):
    """Writes an upright RGB frame ``out_key`` (uint8 [H, W, 3]) at reset and after every step.

    The transform renders straight from the base env's MuJoCo ``model`` and ``data`` with a
    ``mujoco.Renderer`` it owns (one per transform), so it costs what a raw renderer costs.
    ``mujoco.Renderer.render`` makes its own GL context current before drawing, which is what
    keeps several envs rendering in one process correct (Metaworld issue #448, where
    gymnasium's renderer drew into whichever context was current).

    Orientation: Metaworld's ``corner*`` cameras are mounted upside-down (their image-up axis
    points below the horizon), so their raw frames show the table at the top. This transform
    applies a true 180-degree rotation to such cameras: it renders the view of the same camera
    rolled upright about its view axis, which equals ``raw_frame[::-1, ::-1]`` (up to
    rasterisation tie-breaks on about 0.1% of edge pixels) at no cost. Left and right stay where
    they are in the world. The prior implementations flipped the rows only (``frame[::-1]``), an
    upright but mirrored image that no real camera sees. Which cameras are rolled is decided
    once, when the renderer is created, from the sign of the camera's image-up axis in the world
    z direction.

    Speed: with ``fast=True`` (default) shadows, reflections and multisample anti-aliasing are
    off and the skybox is kept (turning it off blacks out the background); on a CPU (Mesa
    llvmpipe) this is about 10x faster than Metaworld's default look, which ``fast=False``
    reproduces. The quality settings are read by MuJoCo when the render context is created, so
    they are applied to the model only while this transform's renderer is built and then
    restored: other renderers of the same model keep their own settings.

    Args:
        camera: name of a camera of the model (Metaworld: ``topview``, ``corner``, ``corner2``,
            ``corner3``, ``corner4``, ``behindGripper``, ``gripperPOV``).
        image_size: side of the square frame, or ``(height, width)``.
        fast: fast render settings (see above) or Metaworld's default look.
        out_key: where the frame is written.

    The base env must expose its MuJoCo ``model`` and ``data`` (as
    :class:`~temporal_torchrl.envs.metaworld_env.MetaworldEnv` does) or wrap a gymnasium MuJoCo
    env (``base_env._env.unwrapped.model``). Call :meth:`switch` to stop and resume rendering:
    while off, no frame is written. Outside an env (on replay-buffer data) the transform is the
    identity: a frame can only be rendered from a live simulator.

    Example:
        >>> from torchrl.envs import TransformedEnv
        >>> from temporal_torchrl.envs.metaworld_env import MetaworldEnv
        >>> from temporal_torchrl.transforms import RenderTransform
        >>> env = TransformedEnv(MetaworldEnv("push", max_episode_steps=3),
        ...                      RenderTransform(image_size=64))
        >>> env.rollout(3)["next", "pixels"].shape
        torch.Size([3, 64, 64, 3])
    """

    def __init__(self, camera: str = defaults.CAMERA,
                 image_size: int | tuple[int, int] = defaults.IMAGE_SIZE,
                 fast: bool = defaults.FAST_RENDER, out_key: str = "pixels") -> None:
        height, width = _parse_image_size(image_size)
        if not isinstance(camera, str) or not camera:
            raise ValueError(
                f"camera={camera!r} is not a camera name: pass a name such as 'corner2'."
            )
        super().__init__(in_keys=[], out_keys=[out_key])
        self.camera = camera
        self.height = height
        self.width = width
        self.fast = fast
        self.out_key = out_key
        self.enabled = True
        self._renderer: mujoco.Renderer | None = None
        self._mjv_camera: mujoco.MjvCamera | None = None
        self._data: mujoco.MjData | None = None
        self._rotate = False

    # ----------------------------------------------------------------------------- set-up
    @staticmethod
    def camera_names(model: mujoco.MjModel) -> list[str]:
        """Names of the cameras defined in ``model``."""
        return [model.camera(index).name for index in range(model.ncam)]

    def validate_camera(self, model: mujoco.MjModel) -> None:
        """Raise a ValueError naming the valid cameras when ``self.camera`` is not in ``model``."""
        names = self.camera_names(model)
        if self.camera not in names:
            raise ValueError(
                f"Unknown camera {self.camera!r}: this model has the cameras {names}; "
                "pass one of them as camera=... (the prior implementations use 'corner2')."
            )

    def _mujoco_model_and_data(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        parent = self.parent
        base_env = parent.base_env if parent is not None else None
        for owner in (base_env, getattr(getattr(base_env, "_env", None), "unwrapped", None)):
            model = getattr(owner, "model", None)
            data = getattr(owner, "data", None)
            if isinstance(model, mujoco.MjModel) and isinstance(data, mujoco.MjData):
                return model, data
        raise ValueError(
            f"RenderTransform needs a MuJoCo-based env, got base env {type(base_env).__name__} "
            "without MuJoCo `model`/`data`: append it to a TransformedEnv around "
            "temporal_torchrl.envs.make_env(...) (or a gymnasium MuJoCo env), inside each "
            "worker of a batched env rather than around the batched env."
        )

    def _build_renderer(self) -> None:
        _refuse_forked_after_rendering()
        match_mujoco_backend()
        model, data = self._mujoco_model_and_data()
        self.validate_camera(model)
        quality, global_ = model.vis.quality, model.vis.global_
        saved = (quality.shadowsize, quality.offsamples, global_.offwidth, global_.offheight)
        # The offscreen buffer must hold the frame; the quality settings are read when the
        # render context is created. Both are restored right after.
        global_.offwidth = max(global_.offwidth, self.width)
        global_.offheight = max(global_.offheight, self.height)
        if self.fast:
            quality.shadowsize = 0
            quality.offsamples = 0
        try:
            renderer = mujoco.Renderer(model, height=self.height, width=self.width)
        finally:
            quality.shadowsize, quality.offsamples, global_.offwidth, global_.offheight = saved
        if self.fast:
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, self.camera)
        mjv_camera = mujoco.MjvCamera()
        mjv_camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        mjv_camera.fixedcamid = camera_id
        # Column 1 of the camera frame is its image-up axis; pointing down means upside-down.
        # Metaworld's envs keep `data` forwarded, so cam_xmat is current.
        self._rotate = bool(data.cam_xmat[camera_id].reshape(3, 3)[2, 1] < 0)
        self._renderer, self._mjv_camera, self._data = renderer, mjv_camera, data
        global _RENDERING_PID
        _RENDERING_PID = os.getpid()
        _register_exit_cleanup()
        _LIVE_TRANSFORMS.add(self)

    # --------------------------------------------------------------------------- rendering
    def render(self) -> torch.Tensor:
        """Render the env's current state: uint8 [H, W, 3], upright."""
        if self._renderer is None:
            self._build_renderer()
        self._renderer.update_scene(self._data, self._mjv_camera)
        if self._rotate:
            # Roll the OpenGL camera by 180 degrees about its view axis instead of rotating the
            # image afterwards: it is free, while copying a 224x224 frame with negative strides
            # costs about 0.5 ms. The view frustum is mirrored with it (it is symmetric for
            # Metaworld's cameras, so this is a no-op there).
            for gl_camera in self._renderer.scene.camera:
                gl_camera.up[:] = -gl_camera.up
                gl_camera.frustum_center = -gl_camera.frustum_center
                gl_camera.frustum_bottom, gl_camera.frustum_top = (
                    -gl_camera.frustum_top, -gl_camera.frustum_bottom)
        return torch.from_numpy(self._renderer.render())

    def switch(self, mode: bool | None = None) -> None:
        """Turn rendering on (``True``), off (``False``) or toggle it (``None``); the env's
        specs follow (``out_key`` is declared only while rendering is on)."""
        self.enabled = (not self.enabled) if mode is None else bool(mode)
        self.out_keys = [self.out_key] if self.enabled else []  # TorchRL checks them in the spec
        container = self.container
        while container is not None and not isinstance(container, EnvBase):
            container = getattr(container, "container", None)
        if container is not None:
            container.empty_cache()  # the env's cached specs are recomputed from ours

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        if self.enabled:
            frame = self.render()
            parent = self.parent
            if parent is not None and parent.device is not None:
                frame = frame.to(parent.device)
            next_tensordict.set(self.out_key, frame)
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase,
               tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        # Stored transitions cannot be re-rendered: on replay-buffer data this is the identity.
        return tensordict

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        if self.enabled:
            observation_spec[self.out_key] = Bounded(
                0, 255, (*observation_spec.shape, self.height, self.width, 3),
                dtype=torch.uint8, device=observation_spec.device,
            )
        return observation_spec

    def clone(self) -> RenderTransform:
        # A clone renders its own env: it must not share this transform's renderer.
        copy = super().clone()
        copy._renderer, copy._mjv_camera, copy._data = None, None, None
        return copy

    def close(self) -> None:
        """Free the renderer's GL resources (also done when the transform is garbage-collected)."""
        if self._renderer is not None:
            self._renderer.close()
        self._renderer, self._mjv_camera, self._data = None, None, None

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(camera={self.camera!r}, image_size=({self.height}, "
                f"{self.width}), fast={self.fast}, out_key={self.out_key!r}, "
                f"enabled={self.enabled})")


# Renderers still alive at interpreter exit must be closed before MuJoCo terminates the EGL
# display (an exit hook it registers when the first GL context is created); freed later, by the
# garbage collector, their contexts print EGLError tracebacks. Exit hooks run last-in first-out,
# so ours is registered after the first renderer exists.
_LIVE_TRANSFORMS: weakref.WeakSet[RenderTransform] = weakref.WeakSet()
_EXIT_CLEANUP_REGISTERED = False


def _close_live_renderers() -> None:
    for transform in list(_LIVE_TRANSFORMS):
        transform.close()


def _register_exit_cleanup() -> None:
    global _EXIT_CLEANUP_REGISTERED
    if not _EXIT_CLEANUP_REGISTERED:
        atexit.register(_close_live_renderers)
        _EXIT_CLEANUP_REGISTERED = True


# The process that created a renderer. A child forked from it inherits its EGL display state,
# and MuJoCo's renderer set-up in the child then waits forever (the parent spinning at 100% CPU
# in a ParallelEnv with mp_start_method="fork"). Refusing at once names the fix instead.
_RENDERING_PID: int | None = None


def _refuse_forked_after_rendering() -> None:
    if _RENDERING_PID is not None and _RENDERING_PID != os.getpid():
        raise RuntimeError(
            f"RenderTransform: this process (pid {os.getpid()}) was forked from process "
            f"{_RENDERING_PID} after that one had rendered, and MuJoCo's EGL renderer set-up "
            "hangs in such a child. Start the workers with spawn, "
            "ParallelEnv(..., mp_start_method=\"spawn\") (TorchRL's default), or create them "
            "before the parent renders anything.")


def _parse_image_size(image_size: int | tuple[int, int]) -> tuple[int, int]:
    sizes = (image_size, image_size) if isinstance(image_size, (int, np.integer)) \
        else tuple(image_size) if isinstance(image_size, (tuple, list)) else None
    if (sizes is None or len(sizes) != 2 or isinstance(image_size, bool)
            or not all(isinstance(s, (int, np.integer)) and s > 0 for s in sizes)):
        raise ValueError(
            f"image_size={image_size!r} is not a positive frame size: pass a positive integer "
            "(square frames, e.g. 224) or a (height, width) pair of positive integers."
        )
    return int(sizes[0]), int(sizes[1])
