"""Motion clips for the G1: load, validate, resample, differentiate, infer sole contacts.

Clip layouts accepted (both are Pinocchio configurations row by row, which is also the layout of
the public G1 retargeted LAFAN1 clips):

* CSV, no header, one frame per row, 36 columns: base position xyz [m], base quaternion xyzw,
  then the 29 joint angles [rad] in the order of :data:`robots.g1.JOINTS`; the frame rate is a
  parameter (LAFAN1: 30 fps).
* NPZ with either ``qpos`` (T, 36) in the CSV layout, or ``root_pos`` (T, 3), ``root_quat_xyzw``
  (T, 4) and ``joint_pos`` (T, 29); an optional scalar ``fps`` overrides the configured rate.

Pipeline (:func:`load_motion_clip`): validate -> normalise quaternions -> resample to the target
rate (cubic splines for positions and joints, spherical linear interpolation for the base
orientation) -> velocities and accelerations (:func:`differentiate`) -> contacts
(:func:`infer_contacts`) -> a :class:`~optimal_control.reference.Reference` with one phase.

**Differentiation** (:func:`differentiate`): central differences on the configuration manifold,
``v_t = pin.difference(q_{t-1}, q_{t+1}) / (2 dt)`` (one-sided at the ends), then a
Savitzky-Golay filter (window ``smoothing_window_s``, polynomial order ``polyorder``) smooths ``v``
and its derivative gives ``a``. The base part of ``v`` is the pelvis twist in the pelvis frame, and
Pinocchio's free-flyer acceleration is the time derivative of exactly those components, so the
filter may run on them directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter
from scipy.spatial.transform import Rotation, Slerp

from optimal_control.files import read_npz
from optimal_control.reference import NQ, Reference
from optimal_control.validation import require_finite_fields
from robots import g1
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model


class ClipError(ValueError):
    """A motion clip is malformed (layout, NaN, limits, quaternions, length)."""


@dataclass(frozen=True)
class ClipConfig:
    """How a motion clip becomes a reference."""

    source_fps: float = 30.0  # frame rate of a CSV clip (NPZ 'fps' overrides) [1/s]
    target_fps: float = 50.0  # frame rate of the reference [1/s]
    smoothing_window_s: float = 0.1  # Savitzky-Golay window for v and a [s]
    polyorder: int = 3  # Savitzky-Golay polynomial order [-]
    min_frames: int = 10  # fewest frames a clip may have [-]
    joint_limit_tolerance_rad: float = 0.1  # allowed excursion beyond the URDF limits [rad]
    quat_norm_tolerance: float = 0.05  # allowed | |quat| - 1 | before the clip is rejected [-]
    contact_height_m: float = 0.03  # lowest sole corner at most this high: candidate contact [m]
    contact_speed_m_s: float = 0.4  # and sole horizontal speed at most this: contact [m/s]
    ground_to_lowest_sole: bool = True  # shift the clip vertically so its lowest sole is at z=0
    max_frames: int = 0  # keep only the first frames after resampling; 0 = all [-]
    # Plausibility of the base motion between consecutive source frames. A sprinting human peaks
    # near 10 m/s and a G1 backflip leaves the ground at about 3 m/s; 10 m/s flags a glitch (a
    # frame at x = 1e12, a 5 m jump: 150 m/s at 30 fps) or centimetres read as metres.
    max_base_speed_m_s: float = 10.0  # largest base speed between two frames [m/s]
    # 300 m/s^2 (about 30 g) is above landing impacts (about 3 m/s lost within 1/120 s) and mocap
    # noise at 120 fps (1 mm jitter: about 30 m/s^2), below a one-frame 0.2 m spike at 30 fps.
    max_base_acceleration_m_s2: float = 300.0  # largest base acceleration over 3 frames [m/s^2]

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field and its flag."""
        require_finite_fields(self)


def read_clip(path: str | Path, cfg: ClipConfig = ClipConfig()) -> tuple[np.ndarray, float]:
    """Raw clip rows (T, 36) and their frame rate [1/s] from a CSV or NPZ file."""
    path = Path(path)
    if not path.is_file():
        raise ClipError(f"Motion clip '{path}' does not exist or is not a file; check --clip.")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        try:
            rows = np.loadtxt(path, delimiter=",", ndmin=2)
        except ValueError as err:
            raise ClipError(
                f"Motion clip '{path}' is not a numeric CSV without header: {err}"
            ) from err
        return rows, cfg.source_fps
    if suffix == ".npz":
        try:
            npz = read_npz(path, "Motion clip")
        except ValueError as err:
            raise ClipError(str(err)) from err
        keys = set(npz)
        fps = cfg.source_fps
        if "fps" in keys:
            if npz["fps"].size != 1 or not np.issubdtype(npz["fps"].dtype, np.number):
                raise ClipError(
                    f"Motion clip '{path}': 'fps' must be one number (frames per second), got "
                    f"an array of shape {npz['fps'].shape} and dtype {npz['fps'].dtype}."
                )
            fps = float(npz["fps"].reshape(()))
        try:
            if "qpos" in keys:
                return np.asarray(npz["qpos"], dtype=float), fps
            needed = {"root_pos", "root_quat_xyzw", "joint_pos"}
            if not needed <= keys:
                raise ClipError(
                    f"Motion clip '{path}' has arrays {sorted(keys)}; expected 'qpos' (T, 36) or "
                    f"{sorted(needed)}."
                )
            parts = [np.asarray(npz[k], dtype=float) for k in ("root_pos", "root_quat_xyzw")]
            parts.append(np.asarray(npz["joint_pos"], dtype=float))
            return np.concatenate(parts, axis=1), fps
        except (ValueError, TypeError) as err:
            if isinstance(err, ClipError):
                raise
            raise ClipError(f"Motion clip '{path}': arrays do not line up: {err}") from err
    raise ClipError(f"Motion clip '{path}': unknown format '{suffix}'; use .csv or .npz.")


def validate_clip(
    rows: np.ndarray,
    fps: float,
    cfg: ClipConfig = ClipConfig(),
    robot: G1Pinocchio | None = None,
    source: str = "clip",
) -> np.ndarray:
    """Check a raw clip (T, 36) and return it with unit quaternions. Raises :class:`ClipError`."""
    robot = robot or build_pinocchio_model()
    rows = np.asarray(rows, dtype=float)
    if rows.ndim != 2 or rows.shape[1] != NQ:
        raise ClipError(
            f"{source}: expected {NQ} columns per frame (base xyz, quaternion xyzw, "
            f"{g1.NUM_JOINTS} joints), got shape {rows.shape}."
        )
    if not (np.isfinite(fps) and fps > 0):
        raise ClipError(f"{source}: frame rate must be a finite number > 0, got {fps}.")
    if rows.shape[0] < cfg.min_frames:
        raise ClipError(f"{source}: {rows.shape[0]} frames, at least {cfg.min_frames} are needed.")
    bad = ~np.isfinite(rows)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise ClipError(f"{source}: NaN/inf at frame {row}, column {col}.")
    check_base_motion(rows[:, :3], fps, cfg, source)
    norms = np.linalg.norm(rows[:, 3:7], axis=1)
    worst = int(np.argmax(np.abs(norms - 1.0)))
    if abs(norms[worst] - 1.0) > cfg.quat_norm_tolerance:
        raise ClipError(
            f"{source}: base quaternion (columns 3-6, xyzw) of frame {worst} has norm "
            f"{norms[worst]:.4f}, not 1; is the layout xyz + xyzw + joints?"
        )
    joints = rows[:, 7:]
    tol = cfg.joint_limit_tolerance_rad
    below = robot.position_lower_rad - tol - joints
    above = joints - robot.position_upper_rad - tol
    excess = np.maximum(below, above)
    if np.any(excess > 0):
        row, j = (int(i) for i in np.unravel_index(np.argmax(excess), excess.shape))
        raise ClipError(
            f"{source}: joint '{g1.JOINT_NAMES[j]}' = {joints[row, j]:.3f} rad at frame {row} is "
            f"outside its limits [{robot.position_lower_rad[j]:.3f}, "
            f"{robot.position_upper_rad[j]:.3f}] by more than {tol} rad; is the joint order "
            "that of robots.g1.JOINTS?"
        )
    out = rows.copy()
    out[:, 3:7] /= norms[:, None]
    return out


def check_base_motion(
    base_w: np.ndarray, fps: float, cfg: ClipConfig = ClipConfig(), source: str = "clip"
) -> None:
    """Reject a physically implausible base path (T, 3) [m] sampled at ``fps`` [1/s].

    The speed between consecutive frames must stay below ``cfg.max_base_speed_m_s`` and the
    second difference (acceleration over three frames) below ``cfg.max_base_acceleration_m_s2``;
    the message names the first offending frame. Raises :class:`ClipError`.
    """
    if base_w.shape[0] < 2:
        return
    speed = np.linalg.norm(np.diff(base_w, axis=0), axis=1) * fps
    k = int(np.argmax(speed))
    if speed[k] > cfg.max_base_speed_m_s:
        raise ClipError(
            f"{source}: the base moves {speed[k] / fps:.3g} m between frames {k} and {k + 1} "
            f"({speed[k]:.3g} m/s at {fps:g} fps), above the plausible "
            f"{cfg.max_base_speed_m_s:g} m/s (--clip-max-base-speed-m-s); fix the glitch, check "
            "that positions are in metres and the frame rate is right."
        )
    if base_w.shape[0] < 3:
        return
    accel = np.linalg.norm(np.diff(base_w, n=2, axis=0), axis=1) * fps**2
    k = int(np.argmax(accel))
    if accel[k] > cfg.max_base_acceleration_m_s2:
        raise ClipError(
            f"{source}: base acceleration {accel[k]:.3g} m/s^2 around frame {k + 1} is above the "
            f"plausible {cfg.max_base_acceleration_m_s2:g} m/s^2 "
            "(--clip-max-base-acceleration-m-s2); fix the glitch or check the frame rate."
        )


def resample(rows: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Resample configurations (T, 36) to ``fps_out`` over the same time span.

    Base position and joints: cubic splines; base orientation: spherical linear interpolation.
    """
    t_in = np.arange(rows.shape[0]) / fps_in
    t_out = np.arange(int(np.floor(t_in[-1] * fps_out + 1e-9)) + 1) / fps_out
    out = np.empty((t_out.shape[0], rows.shape[1]))
    spline = CubicSpline(t_in, np.concatenate([rows[:, :3], rows[:, 7:]], axis=1), axis=0)
    values = spline(t_out)
    out[:, :3] = values[:, :3]
    out[:, 7:] = values[:, 3:]
    out[:, 3:7] = Slerp(t_in, Rotation.from_quat(rows[:, 3:7]))(t_out).as_quat()  # xyzw
    return out


def differentiate(
    q: np.ndarray,
    dt: float,
    smoothing_window_s: float = 0.1,
    polyorder: int = 3,
    robot: G1Pinocchio | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations (T, 35) of configurations (T, 36) sampled every ``dt``.

    See the module docstring for the rule (manifold central differences + Savitzky-Golay).
    """
    robot = robot or build_pinocchio_model()
    model = robot.model
    num = q.shape[0]
    if num < 2:
        return np.zeros((num, model.nv)), np.zeros((num, model.nv))
    v = np.empty((num, model.nv))
    for t in range(num):
        lo, hi = max(t - 1, 0), min(t + 1, num - 1)
        v[t] = pin.difference(model, q[lo], q[hi]) / ((hi - lo) * dt)
    window = int(round(smoothing_window_s / dt)) | 1  # odd
    window = min(window, num if num % 2 else num - 1)
    if window > polyorder + 1:
        v_smooth = savgol_filter(v, window, polyorder, axis=0, mode="interp")
        a = savgol_filter(v, window, polyorder, deriv=1, delta=dt, axis=0, mode="interp")
    else:
        v_smooth = v
        a = np.gradient(v, dt, axis=0)
    return v_smooth, a


def sole_corner_heights_m(q: np.ndarray, robot: G1Pinocchio | None = None) -> np.ndarray:
    """Lowest sole-corner height per frame and sole (T, 2) and sole origins (T, 2, 3) [m]."""
    robot = robot or build_pinocchio_model()
    data = robot.data()
    corners = g1.sole_corners_m()
    heights = np.empty((q.shape[0], 2))
    origins = np.empty((q.shape[0], 2, 3))
    for t in range(q.shape[0]):
        pin.framesForwardKinematics(robot.model, data, q[t])
        for s, name in enumerate(g1.SOLE_FRAMES):
            placement = data.oMf[robot.frame_ids[name]]
            world = corners @ placement.rotation.T + placement.translation
            heights[t, s] = world[:, 2].min()
            origins[t, s] = placement.translation
    return heights, origins


def infer_contacts(
    q: np.ndarray,
    dt: float,
    height_m: float = 0.03,
    speed_m_s: float = 0.4,
    robot: G1Pinocchio | None = None,
) -> np.ndarray:
    """Sole contacts (T, 2) bool [left, right]: lowest corner low enough and sole slow enough.

    Single-frame flickers are removed (a frame takes the value of both neighbours when they agree).
    """
    heights, origins = sole_corner_heights_m(q, robot)
    speed = np.linalg.norm(np.gradient(origins[..., :2], dt, axis=0), axis=-1)
    contacts = (heights <= height_m) & (speed <= speed_m_s)
    if contacts.shape[0] >= 3:
        same = contacts[:-2] == contacts[2:]
        middle = contacts[1:-1]
        middle[same] = contacts[:-2][same]
    return contacts


def reference_from_configurations(
    q: np.ndarray,
    dt: float,
    cfg: ClipConfig = ClipConfig(),
    name: str = "clip",
    phase_names: tuple[str, ...] = ("dance",),
    contacts: np.ndarray | None = None,
    robot: G1Pinocchio | None = None,
) -> Reference:
    """Reference from configurations (T, 36) at step ``dt``: differentiate, infer contacts."""
    robot = robot or build_pinocchio_model()
    q = np.array(q, dtype=float)
    if cfg.ground_to_lowest_sole:
        heights, _ = sole_corner_heights_m(q, robot)
        q[:, 2] -= heights.min()
    v, a = differentiate(q, dt, cfg.smoothing_window_s, cfg.polyorder, robot)
    if contacts is None:
        contacts = infer_contacts(q, dt, cfg.contact_height_m, cfg.contact_speed_m_s, robot)
    num = q.shape[0]
    return Reference(
        time_s=np.arange(num) * dt,
        q=q,
        v=v,
        a=a,
        contacts=contacts,
        phase=np.zeros(num, dtype=np.int64),
        phase_names=phase_names,
        dt=dt,
        name=name,
    ).validate()


def load_motion_clip(
    path: str | Path, cfg: ClipConfig = ClipConfig(), name: str = "dance"
) -> Reference:
    """Load, validate, resample and differentiate a clip file into a one-phase reference."""
    robot = build_pinocchio_model()
    rows, fps = read_clip(path, cfg)
    rows = validate_clip(rows, fps, cfg, robot, source=f"Motion clip '{path}'")
    q = resample(rows, fps, cfg.target_fps)
    if cfg.max_frames > 0:
        q = q[: cfg.max_frames]
    return reference_from_configurations(q, 1.0 / cfg.target_fps, cfg, name=name, robot=robot)
