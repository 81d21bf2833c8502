"""Render a :class:`~optimal_control.reference.Reference` to an mp4 with MuJoCo (kinematic replay).

Offscreen rendering uses EGL unless ``MUJOCO_GL`` is already set (``egl`` works on CPU with Mesa
here; ``osmesa`` is not installed). The robot is posed frame by frame (no physics); an optional
per-frame pelvis wrench is drawn as an arrow at the pelvis CoM (force direction, length scaled).
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from optimal_control.reference import Reference
from robots.conventions import pin_to_mj_qpos
from robots.mujoco_model import build_mujoco_model

os.environ.setdefault("MUJOCO_GL", "egl")  # effective only if mujoco is not imported yet

import mujoco  # noqa: E402
from mujoco.rendering.classic import gl_context  # noqa: E402


def _ensure_offscreen_backend() -> None:
    """Use EGL when mujoco was imported (by another module) before MUJOCO_GL was set.

    mujoco picks its GL backend when first imported; without a display the default (GLFW) cannot
    open a context. If MUJOCO_GL now asks for EGL, point the renderer at MuJoCo's EGL context.
    """
    wanted = os.environ.get("MUJOCO_GL", "").lower()
    if wanted == "egl" and gl_context._MUJOCO_GL != "egl" and not os.environ.get("DISPLAY"):
        from mujoco.egl import GLContext

        gl_context.GLContext = GLContext


class RenderUnavailableError(RuntimeError):
    """Offscreen rendering could not start (no EGL/OSMesa) or video encoding is missing."""


@dataclass(frozen=True)
class RenderConfig:
    """Video options."""

    width: int = 640  # frame width [px]
    height: int = 360  # frame height [px]
    fps: float = 0.0  # video frame rate; 0 = real time (1 / (reference dt x frame_stride)) [1/s]
    frame_stride: int = 2  # render every n-th reference frame (CPU rendering is slow) [-]
    max_frames: int = 0  # stop after this many frames; 0 = all [-]
    force_arrow_m_per_n: float = 0.01  # arrow length per newton of pelvis force [m/N]
    camera_distance_m: float = 3.0  # tracking camera distance to the pelvis [m]
    camera_azimuth_deg: float = 135.0  # tracking camera azimuth (0 = looking along +x) [deg]
    camera_elevation_deg: float = -15.0  # tracking camera elevation [deg]


def _add_arrow(scene, start: np.ndarray, vec: np.ndarray) -> None:
    if scene.ngeom >= scene.maxgeom or np.linalg.norm(vec) < 1e-6:
        return
    geom = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(
        geom,
        mujoco.mjtGeom.mjGEOM_ARROW,
        np.zeros(3),
        np.zeros(3),
        np.zeros(9),
        np.array([1.0, 0.2, 0.2, 1.0], dtype=np.float32),
    )
    mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_ARROW, 0.01, start, start + vec)
    scene.ngeom += 1


def render_reference(
    ref: Reference,
    path: str | Path,
    cfg: RenderConfig = RenderConfig(),
    wrench_w: np.ndarray | None = None,
) -> Path:
    """Write an mp4 of ``ref`` to ``path``; ``wrench_w`` (T, 6) draws the pelvis force arrow.

    Raises:
        RenderUnavailableError: when no offscreen GL context can be created or the video writer
            (imageio-ffmpeg) is missing.
    """
    try:
        import imageio.v2 as imageio
    except ImportError as err:
        raise RenderUnavailableError(
            "Video needs imageio and imageio-ffmpeg: pip install imageio imageio-ffmpeg"
        ) from err
    model = copy.deepcopy(build_mujoco_model())  # the cached model is shared: edit a copy
    model.vis.headlight.ambient[:] = 0.45
    model.vis.headlight.diffuse[:] = 0.6
    data = mujoco.MjData(model)
    _ensure_offscreen_backend()
    try:
        renderer = mujoco.Renderer(model, height=cfg.height, width=cfg.width)
    except Exception as err:  # mujoco raises various GL errors; all mean "no renderer here"
        raise RenderUnavailableError(
            f"MuJoCo offscreen rendering failed with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: "
            f"{err}. Install EGL (libegl1) or OSMesa, or set MUJOCO_GL."
        ) from err
    pelvis = model.body("pelvis").id
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = pelvis
    camera.distance = cfg.camera_distance_m
    camera.azimuth = cfg.camera_azimuth_deg
    camera.elevation = cfg.camera_elevation_deg
    stride = max(1, cfg.frame_stride)
    fps = cfg.fps or 1.0 / (ref.dt * stride)
    frames = list(range(0, ref.num_frames, stride))
    if cfg.max_frames > 0:
        frames = frames[: cfg.max_frames]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Written beside the target and renamed at the end: a kill mid-video leaves no torn mp4.
    tmp = path.with_name(f".{path.stem}.partial{os.getpid()}{path.suffix}")
    try:
        with imageio.get_writer(tmp, fps=fps, macro_block_size=1) as writer:
            for t in frames:
                data.qpos[:] = pin_to_mj_qpos(ref.q[t])
                mujoco.mj_forward(model, data)
                renderer.update_scene(data, camera=camera)
                if wrench_w is not None:
                    start = data.xipos[pelvis].copy()
                    _add_arrow(renderer.scene, start, cfg.force_arrow_m_per_n * wrench_w[t, :3])
                writer.append_data(renderer.render())
        os.replace(tmp, path)
    finally:
        renderer.close()
        tmp.unlink(missing_ok=True)
    return path
