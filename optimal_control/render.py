"""Render a :class:`~optimal_control.reference.Reference` to an mp4 with MuJoCo (kinematic replay).

Offscreen rendering uses EGL unless ``MUJOCO_GL`` is already set (``egl`` works on CPU with Mesa
here; ``osmesa`` is not installed). The robot is posed frame by frame (no physics); an optional
per-frame pelvis wrench is drawn as an arrow at the pelvis CoM (force direction, length scaled),
and an optional second pose per frame (e.g. the reference a policy tracks) as a translucent ghost,
overlaid on the robot or beside it.
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


def check_offscreen_rendering() -> None:
    """Raise :class:`RenderUnavailableError` (saying what to install or set) when no video can be
    made here: imageio missing, or no offscreen GL context for a tiny scene. Cheap (a 16 x 16
    renderer), so a command asked for a video checks it before its rollout."""
    try:
        import imageio.v2  # noqa: F401
    except ImportError as err:
        raise RenderUnavailableError(
            "Video needs imageio and imageio-ffmpeg: pip install imageio imageio-ffmpeg"
        ) from err
    _ensure_offscreen_backend()
    try:
        renderer = mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 16, 16)
        renderer.render()
        renderer.close()
    except Exception as err:  # mujoco raises various GL errors; all mean "no renderer here"
        raise RenderUnavailableError(
            f"MuJoCo offscreen rendering failed with MUJOCO_GL={os.environ.get('MUJOCO_GL')} "
            f"({type(err).__name__}: {str(err).strip().splitlines()[0] if str(err).strip() else ''}"
            "): set MUJOCO_GL=egl with EGL installed (libegl1), or install OSMesa (libosmesa6)"
        ) from err


@dataclass(frozen=True)
class RenderConfig:
    """Video options."""

    width: int = 640  # frame width [px]
    height: int = 360  # frame height [px]
    fps: float = 0.0  # video frame rate; 0 = real time (1 / (reference dt x frame_stride)) [1/s]
    frame_stride: int = 2  # render every n-th reference frame (CPU rendering is slow) [-]
    max_frames: int = 0  # stop after this many frames; 0 = all [-]
    force_arrow_m_per_n: float = 0.01  # arrow length per newton of pelvis force [m/N]
    camera_distance_m: float = 3.0  # camera to the robot's CoM (with a ghost: to the midpoint) [m]
    camera_azimuth_deg: float = 135.0  # camera azimuth (0 = looking along +x) [deg]
    camera_elevation_deg: float = -15.0  # camera elevation [deg]
    ghost_rgba: tuple[float, ...] = (0.2, 0.55, 1.0, 0.3)  # ghost red, green, blue, opacity [0-1]
    ghost_side_m: float = 0.0  # ghost shift to the camera's right (< 0: left); 0: at its pose [m]
    overlay_text: bool = True  # print the time (and which pose is the ghost) top left [-]

    def __post_init__(self) -> None:
        if len(self.ghost_rgba) != 4 or not all(0.0 <= c <= 1.0 for c in self.ghost_rgba):
            raise ValueError(
                f"ghost_rgba takes 4 values in [0, 1] (red, green, blue, opacity), got "
                f"{self.ghost_rgba}"
            )


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


def _add_ghost(scene, model, ghost_data, vopt, pert, rgba: tuple[float, ...]) -> None:
    """Append the moving geoms of ``ghost_data``'s pose to ``scene``, flat-coloured ``rgba``."""
    first = scene.ngeom
    mujoco.mjv_addGeoms(model, ghost_data, vopt, pert, mujoco.mjtCatBit.mjCAT_DYNAMIC, scene)
    for i in range(first, scene.ngeom):
        geom = scene.geoms[i]
        geom.rgba[:] = rgba
        geom.matid = -1  # no texture: one flat colour reads as "not the robot"


def _camera_right_w(azimuth_deg: float) -> np.ndarray:
    """Unit vector (3,) pointing to the right of the image for a camera at ``azimuth_deg``."""
    az = np.deg2rad(azimuth_deg)
    return np.array([np.sin(az), -np.cos(az), 0.0])  # forward x up, forward = (cos az, sin az, .)


def _draw_text(frame: np.ndarray, lines: list[str]) -> np.ndarray:
    """``frame`` (H, W, 3) uint8 with ``lines`` printed in its top-left corner."""
    from PIL import Image, ImageDraw, ImageFont  # imageio's own dependency

    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    size = max(10, frame.shape[0] // 24)
    font = ImageFont.load_default(size=size)
    for k, line in enumerate(lines):
        xy = (6, 4 + k * (size + 4))
        draw.text(xy, line, fill=(255, 255, 255), font=font, stroke_width=2, stroke_fill=(0, 0, 0))
    return np.asarray(image)


def render_reference(
    ref: Reference,
    path: str | Path,
    cfg: RenderConfig = RenderConfig(),
    wrench_w: np.ndarray | None = None,
    ghost_q: np.ndarray | None = None,
    labels: tuple[str, str] = ("robot", "reference"),
    captions: list[str] | None = None,
) -> Path:
    """Write an mp4 of ``ref`` to ``path``; ``wrench_w`` (T, 6) draws the pelvis force arrow.
    ``captions`` (T,): a line of text per frame under the time (a walk's command).

    ``ghost_q`` (T, nq), Pinocchio layout like ``ref.q``, frame for frame: a second G1 drawn as
    a translucent ghost (``cfg.ghost_rgba``), shifted ``cfg.ghost_side_m`` to the camera's right;
    the camera then looks at the midpoint of the two (both stay in view). ``labels``: the names
    of the solid pose and the ghost in the overlay text.

    Raises:
        ValueError: when ``ghost_q`` is not one configuration per frame of ``ref``.
        RenderUnavailableError: when no offscreen GL context can be created or the video writer
            (imageio-ffmpeg) is missing.
    """
    if captions is not None and len(captions) != ref.num_frames:
        raise ValueError(
            f"captions must hold one line per frame of the reference ({ref.num_frames}), got "
            f"{len(captions)}"
        )
    if ghost_q is not None:
        ghost_q = np.asarray(ghost_q, dtype=float)
        if ghost_q.shape != ref.q.shape:
            raise ValueError(
                f"ghost_q must hold one configuration per frame of the reference, shape "
                f"{ref.q.shape} (Pinocchio layout), got {ghost_q.shape}"
            )
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
    ghost_data = mujoco.MjData(model) if ghost_q is not None else None
    vopt, pert = mujoco.MjvOption(), mujoco.MjvPerturb()
    ghost_shift_w = cfg.ghost_side_m * _camera_right_w(cfg.camera_azimuth_deg)
    _ensure_offscreen_backend()
    try:
        renderer = mujoco.Renderer(model, height=cfg.height, width=cfg.width)
    except Exception as err:  # mujoco raises various GL errors; all mean "no renderer here"
        raise RenderUnavailableError(
            f"MuJoCo offscreen rendering failed with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: "
            f"{err}. Install EGL (libegl1) or OSMesa, or set MUJOCO_GL."
        ) from err
    pelvis = model.body("pelvis").id
    camera = mujoco.MjvCamera()  # free, its target set every frame: the robot (and its ghost)
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
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
                camera.lookat[:] = data.subtree_com[pelvis]  # the whole robot's CoM
                if ghost_data is not None:
                    ghost_data.qpos[:] = pin_to_mj_qpos(ghost_q[t])
                    ghost_data.qpos[:3] += ghost_shift_w
                    mujoco.mj_kinematics(model, ghost_data)
                    mujoco.mj_comPos(model, ghost_data)
                    camera.lookat[:] = 0.5 * (camera.lookat + ghost_data.subtree_com[pelvis])
                renderer.update_scene(data, camera=camera, scene_option=vopt)
                if ghost_data is not None:
                    _add_ghost(renderer.scene, model, ghost_data, vopt, pert, cfg.ghost_rgba)
                if wrench_w is not None:
                    start = data.xipos[pelvis].copy()
                    _add_arrow(renderer.scene, start, cfg.force_arrow_m_per_n * wrench_w[t, :3])
                frame = renderer.render()
                if cfg.overlay_text:
                    lines = [f"t = {ref.time_s[t]:.2f} s"]
                    if ghost_data is not None:
                        lines.append(f"solid: {labels[0]}   ghost: {labels[1]}")
                    if captions is not None and captions[t]:
                        lines.extend(captions[t].split("\n"))
                    frame = _draw_text(frame, lines)
                writer.append_data(frame)
        os.replace(tmp, path)
    finally:
        renderer.close()
        tmp.unlink(missing_ok=True)
    return path
