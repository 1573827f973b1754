"""RenderTransform: upright frames, declared specs, fast vs default look, several envs, switch."""

import multiprocessing
import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.envs import make_env
from temporal_torchrl.envs.metaworld_env import MetaworldEnv
from temporal_torchrl.params import EnvParams
from temporal_torchrl.transforms import RenderTransform

SIZE = 64


def _red(frame: np.ndarray) -> np.ndarray:
    """The robot arm."""
    return (frame[..., 0] > 100) & (frame[..., 0] > 2 * frame[..., 1]) & (
        frame[..., 0] > 2 * frame[..., 2])


def _green(frame: np.ndarray) -> np.ndarray:
    """The drawer of drawer-open."""
    return (frame[..., 1] > frame[..., 0] + 40) & (frame[..., 1] > frame[..., 2] + 40)


def _brown(frame: np.ndarray) -> np.ndarray:
    """The wooden table top."""
    return (frame[..., 0] > frame[..., 1] + 20) & (frame[..., 1] > frame[..., 2] + 10) & (
        frame[..., 0] < 200)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _project_upright(model, data, camera: str, point: np.ndarray, size: int) -> tuple[int, int]:
    """Pixel (row, column) of a world point seen by ``camera`` rolled upright.

    The camera frame's columns are right, up and backward; rolling a camera whose up axis points
    down by 180 degrees about its view axis negates right and up.
    """
    camera_id = model.camera(camera).id
    rotation = data.cam_xmat[camera_id].reshape(3, 3)
    if rotation[2, 1] < 0:
        rotation = rotation @ np.diag([-1.0, -1.0, 1.0])
    local = rotation.T @ (point - data.cam_xpos[camera_id])
    focal = (size / 2) / np.tan(np.deg2rad(model.cam_fovy[camera_id]) / 2)
    depth = -local[2]
    return int(size / 2 - focal * local[1] / depth), int(size / 2 + focal * local[0] / depth)


def _looks_upright(frame: np.ndarray, drawer_pixel: tuple[int, int]) -> bool:
    """The drawer is where an upright camera sees it and the table lies in the lower half."""
    table_rows = np.nonzero(_brown(frame))[0]
    return bool(_green(frame)[drawer_pixel]) and table_rows.mean() > frame.shape[0] / 2


def test_frames_are_upright_and_not_mirrored():
    env = make_env("drawer-open", render=True, image_size=SIZE)
    frame = env.reset()["pixels"].numpy()
    base = env.base_env
    drawer_pixel = _project_upright(base.model, base.data, "corner2",
                                    base.data.body("drawer").xpos, SIZE)
    assert _looks_upright(frame, drawer_pixel)
    # The same check rejects the upside-down and the mirrored frame.
    assert not _looks_upright(frame[::-1, ::-1], drawer_pixel)
    assert not _looks_upright(frame[:, ::-1], drawer_pixel)


def test_frame_is_the_raw_render_rotated_by_180_degrees():
    env = make_env("push", render=True, image_size=SIZE)
    frame = env.reset()["pixels"].numpy()
    model, data = env.base_env.model, env.base_env.data
    model.vis.quality.shadowsize, model.vis.quality.offsamples = 0, 0
    with mujoco.Renderer(model, SIZE, SIZE) as renderer:
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        renderer.update_scene(data, "corner2")
        raw = renderer.render()
    # The transform rolls the camera instead of rotating the image: the same picture up to
    # rasterisation tie-breaks on a few edge pixels.
    difference = np.abs(frame.astype(int) - raw[::-1, ::-1])
    assert (difference.max(-1) > 0).mean() < 0.01 and difference.mean() < 0.1
    assert np.abs(frame.astype(int) - raw[::-1]).mean() > 10  # a row flip is a different image


def test_pixels_at_reset_and_every_step_declared_in_the_spec():
    env = make_env("push", render=True, image_size=(SIZE, 48), max_episode_steps=4)
    spec = env.observation_spec["pixels"]
    assert spec.shape == (SIZE, 48, 3) and spec.dtype == torch.uint8
    rollout = env.rollout(4, policy=lambda td: td.set("action", torch.ones(4)))
    for key in ("pixels", ("next", "pixels")):
        assert rollout[key].shape == (4, SIZE, 48, 3) and rollout[key].dtype == torch.uint8
    # Each step's frame is the next step's first frame, and the arm moves.
    assert torch.equal(rollout["next", "pixels"][:-1], rollout["pixels"][1:])
    assert not torch.equal(rollout["pixels"][0], rollout["next", "pixels"][-1])


def test_default_size_is_the_env_params_one():
    """One default frame side for the env and the render transform: EnvParams' (64 px, the
    shipped encoder's); an encoder that reads larger frames refuses far smaller ones."""
    frame = make_env("push", render=True).reset()["pixels"]
    assert frame.shape == (EnvParams().image_size, EnvParams().image_size, 3) == (64, 64, 3)
    assert (RenderTransform().height, RenderTransform().width) == (64, 64)


def test_camera_is_selectable():
    corner2 = make_env("push", render=True, image_size=SIZE).reset()["pixels"]
    topview = make_env("push", render=True, image_size=SIZE, camera="topview").reset()["pixels"]
    assert (corner2.float() - topview.float()).abs().mean() > 20


@pytest.mark.slow
def test_fast_and_default_rendering_show_the_same_scene():
    def frame(task="drawer-open", fast=True, steps=0):
        env = make_env(task, render=True, image_size=SIZE, fast_render=fast)
        tensordict = env.reset()
        for _ in range(steps):
            tensordict["action"] = torch.tensor([1.0, -1.0, 1.0, 0.0])
            tensordict = env.step(tensordict)["next"]
        return tensordict["pixels"].numpy().astype(int)

    fast, default = frame(), frame(fast=False)
    assert not np.array_equal(fast, default)  # shadows, reflections and MSAA do change pixels
    # The same objects at the same pixels: the arm (red) and the drawer (green) ...
    assert _iou(_red(fast), _red(default)) > 0.75
    assert _iou(_green(fast), _green(default)) > 0.75
    # ... which is not the case once the arm has moved, or for another task's scene.
    assert _iou(_red(fast), _red(frame(steps=30))) < 0.7
    assert _iou(_green(fast), _green(frame("door-open"))) < 0.2


def test_two_envs_render_correctly_in_one_process():
    first = make_env("drawer-open", render=True, image_size=SIZE)
    alone = first.reset()["pixels"].clone()
    second = make_env("door-open", render=True, image_size=SIZE)
    other = second.reset()["pixels"]
    assert not torch.equal(alone, other)
    # Interleaved renders (Metaworld issue #448 corrupted the first env's frames here).
    for _ in range(3):
        assert torch.equal(first.reset()["pixels"], alone)
        assert torch.equal(second.reset()["pixels"], other)
    action = TensorDict({"action": torch.tensor([0.5, 0.5, 0.0, 0.0])}, [])
    first_step = first.step(action.clone())["next", "pixels"]
    second.step(action.clone())
    replay = make_env("drawer-open", render=True, image_size=SIZE)
    replay.reset()
    assert torch.equal(replay.step(action.clone())["next", "pixels"], first_step)


def test_switching_off_stops_rendering_and_the_spec_follows():
    env = make_env("push", render=True, image_size=SIZE, max_episode_steps=3)
    env.transform.switch(False)
    assert "pixels" not in env.observation_spec.keys()
    check_env_specs(env)
    rollout = env.rollout(3)
    assert "pixels" not in rollout.keys() and ("next", "pixels") not in rollout.keys(True)
    env.transform.switch()
    assert env.observation_spec["pixels"].shape == (SIZE, SIZE, 3)
    check_env_specs(env)
    assert env.reset()["pixels"].shape == (SIZE, SIZE, 3)


def _render_in_fork(queue) -> None:
    env = TransformedEnv(MetaworldEnv("push", max_episode_steps=3),
                         RenderTransform(image_size=SIZE))
    try:
        env.rollout(2)
        queue.put("rendered")
    except RuntimeError as error:
        queue.put(str(error))


def test_a_child_forked_after_rendering_refuses_at_once_instead_of_hanging():
    # MuJoCo's EGL renderer set-up hangs forever in such a child (the parent of a fork-started
    # ParallelEnv then spins without raising); the transform refuses, naming the fix.
    env = TransformedEnv(MetaworldEnv("push", max_episode_steps=3),
                         RenderTransform(image_size=SIZE))
    env.rollout(2)
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_render_in_fork, args=(queue,))
    child.start()
    child.join(60)
    if child.is_alive():
        child.kill()
        pytest.fail("the forked child hung in the renderer set-up instead of raising")
    message = queue.get(timeout=5)
    assert "forked from process" in message and 'mp_start_method="spawn"' in message


def test_replay_path_is_the_identity_and_transform_needs_a_mujoco_env():
    transform = RenderTransform(image_size=SIZE)
    data = TensorDict({"observation": torch.zeros(5, 39)}, [5])
    assert transform(data) is data and set(data.keys()) == {"observation"}
    with pytest.raises(ValueError, match="MuJoCo"):
        transform.render()


def test_transform_composes_with_a_bare_env():
    env = TransformedEnv(MetaworldEnv("window-close", max_episode_steps=2),
                         RenderTransform(image_size=SIZE, camera="corner3"))
    assert env.rollout(2)["next", "pixels"].shape == (2, SIZE, SIZE, 3)
    with pytest.raises(ValueError, match="camera"):
        TransformedEnv(MetaworldEnv("push"), RenderTransform(camera="nope")).reset()
    with pytest.raises(ValueError, match="camera"):
        RenderTransform(camera="")


@pytest.mark.slow
def test_renders_headless_when_torchrl_is_imported_first():
    # `import torchrl.envs` imports MuJoCo before temporal_torchrl can choose EGL.
    script = ("import torchrl.envs\n"
              "from temporal_torchrl.envs import make_env\n"
              "print(tuple(make_env('push', render=True, image_size=16).reset()['pixels'].shape))")
    environment = {k: v for k, v in os.environ.items()
                   if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    result = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip().endswith("(16, 16, 3)")
