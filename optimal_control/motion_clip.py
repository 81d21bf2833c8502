"""Motion clips for the G1: load, validate, resample, differentiate, infer sole contacts.

Clip layouts accepted (both are Pinocchio configurations row by row, which is also the layout of
the public G1 retargeted LAFAN1 clips):

* CSV, no header, one frame per row, 36 columns: base position xyz [m], base quaternion xyzw,
  then the 29 joint angles [rad] in the order of :data:`robots.g1.JOINTS`; the frame rate is a
  parameter (LAFAN1: 30 fps).
* NPZ with either ``qpos`` (T, 36) in the CSV layout, or ``root_pos`` (T, 3), ``root_quat_xyzw``
  (T, 4) and ``joint_pos`` (T, 29); an optional scalar ``fps`` overrides the configured rate.

Pipeline (:func:`load_motion_clip_with_report`): validate -> normalise quaternions -> remove
single-frame spikes (:func:`despike`) -> resample to the target rate (cubic splines for positions
and joints, spherical linear interpolation for the base orientation) -> shift so the robust ground
estimate (:func:`estimate_ground_m`, a low percentile of the per-frame lowest sole) is z = 0 ->
velocities and accelerations (:func:`differentiate`) -> contacts with hysteresis and a support
fallback (:func:`infer_contacts`) -> a :class:`~optimal_control.reference.Reference` with one
phase, and a plausibility report (:func:`clip_plausibility`: share of frames with no sole down,
largest base jump, ground estimate); too many flying frames is an error, some a warning.

**Differentiation** (:func:`differentiate`): central differences on the configuration manifold,
``v_t = pin.difference(q_{t-1}, q_{t+1}) / (2 dt)`` (one-sided at the ends), then a
Savitzky-Golay filter (window ``smoothing_window_s``, polynomial order ``polyorder``) smooths ``v``
and its derivative gives ``a``. The base part of ``v`` is the pelvis twist in the pelvis frame, and
Pinocchio's free-flyer acceleration is the time derivative of exactly those components, so the
filter may run on them directly.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter
from scipy.spatial.transform import Rotation, Slerp

from optimal_control.files import read_npz
from optimal_control.reference import NQ, Reference
from optimal_control.validation import require_finite_fields, require_ranges
from robots import g1

if TYPE_CHECKING:
    from robots.pinocchio_model import G1Pinocchio


def _robot(robot: G1Pinocchio | None) -> G1Pinocchio:
    """``robot``, or the G1's Pinocchio model. Pinocchio is imported where a function needs it:
    reading an artifact and resampling (:func:`resample`) need none, and the lent GPU machine has
    none (docs/gpu.md, "A GPU visit")."""
    from robots.pinocchio_model import build_pinocchio_model

    return robot or build_pinocchio_model()


class ClipError(ValueError):
    """A motion clip is malformed (layout, NaN, limits, quaternions, length)."""


@dataclass(frozen=True)
class ClipConfig:
    """How a motion clip becomes a reference."""

    source_fps: float = 30.0  # frame rate of a CSV clip (NPZ 'fps' overrides) [1/s]
    target_fps: float = 50.0  # frame rate of the reference [1/s]
    smoothing_window_s: float = 0.2  # Savitzky-Golay window for v and a [s]
    polyorder: int = 3  # Savitzky-Golay polynomial order [-]
    min_frames: int = 10  # fewest frames a clip may have [-]
    joint_limit_tolerance_rad: float = 0.1  # allowed excursion beyond the URDF limits [rad]
    quat_norm_tolerance: float = 0.05  # allowed | |quat| - 1 | before the clip is rejected [-]
    contact_height_m: float = 0.04  # a sole enters contact at most this high above ground [m]
    contact_release_height_m: float = 0.07  # and leaves it only above this height [m]
    contact_speed_m_s: float = 0.4  # a sole enters contact at most this fast horizontally [m/s]
    contact_release_speed_m_s: float = 0.8  # and leaves it only above this speed [m/s]
    support_fallback: bool = True  # no contact and not falling: the lowest sole is [-]
    support_fallback_height_m: float = 0.15  # that lowest sole is at most this high [m]
    ballistic_accel_m_s2: float = 5.0  # base falls faster than this (of g 9.81): airborne [m/s^2]
    ground_to_lowest_sole: bool = True  # shift the clip vertically so the ground estimate is z=0
    ground_percentile: float = 5.0  # ground = this percentile of the per-frame lowest sole [%]
    despike: bool = True  # replace one-frame outliers (Hampel) before resampling [-]
    despike_threshold_m: float = 0.02  # base/joint spike above its 5-frame median [m or rad]
    max_no_contact_share: float = 0.5  # more frames than this without a sole down: error [-]
    warn_no_contact_share: float = 0.1  # more than this: plausibility warning [-]
    max_frames: int = 0  # keep only the first frames after resampling; 0 = all [-]
    # Plausibility of the base motion between consecutive source frames. A sprinting human peaks
    # near 10 m/s and a G1 backflip leaves the ground at about 3 m/s; 10 m/s flags a glitch (a
    # frame at x = 1e12, a 5 m jump: 150 m/s at 30 fps) or centimetres read as metres.
    max_base_speed_m_s: float = 10.0  # largest base speed between two frames [m/s]
    # 300 m/s^2 (about 30 g) is above landing impacts (about 3 m/s lost within 1/120 s) and mocap
    # noise at 120 fps (1 mm jitter: about 30 m/s^2), below a one-frame 0.2 m spike at 30 fps.
    max_base_acceleration_m_s2: float = 300.0  # largest base acceleration over 3 frames [m/s^2]

    def __post_init__(self) -> None:
        """Reject NaN / inf values and values outside any clip, naming the field and its flag."""
        require_finite_fields(self)
        require_ranges(self, {
            "source_fps": (1.0, 10_000.0, "1/s"), "target_fps": (1.0, 10_000.0, "1/s"),
            "smoothing_window_s": (0.0, 5.0, "s"), "polyorder": (0, 20, ""),
            "min_frames": (2, 100_000_000, ""), "joint_limit_tolerance_rad": (0.0, 3.15, "rad"),
            "quat_norm_tolerance": (0.0, 1.0, ""), "contact_height_m": (0.0, 1.0, "m"),
            "contact_release_height_m": (0.0, 1.0, "m"), "contact_speed_m_s": (0.0, 10.0, "m/s"),
            "contact_release_speed_m_s": (0.0, 10.0, "m/s"),
            "support_fallback_height_m": (0.0, 2.0, "m"),
            "ballistic_accel_m_s2": (0.0, 100.0, "m/s^2"), "ground_percentile": (0.0, 100.0, "%"),
            "despike_threshold_m": (0.0, 10.0, "m"), "max_no_contact_share": (0.0, 1.0, ""),
            "warn_no_contact_share": (0.0, 1.0, ""), "max_frames": (0, 100_000_000, ""),
            "max_base_speed_m_s": (0.0, 1000.0, "m/s"),
            "max_base_acceleration_m_s2": (0.0, 100_000.0, "m/s^2"),
        }, prefix="clip_")  # fmt: skip


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
    robot = _robot(robot)
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
        raise ClipError(
            f"{source}: NaN/inf at frame {row}, column {col}; repair the clip or leave those "
            "frames out with --clip-frames A:B."
        )
    check_base_motion(rows[:, :3], fps, cfg, source)
    norms = np.linalg.norm(rows[:, 3:7], axis=1)
    worst = int(np.argmax(np.abs(norms - 1.0)))
    if abs(norms[worst] - 1.0) > cfg.quat_norm_tolerance:
        raise ClipError(
            f"{source}: base quaternion (columns 3-6, xyzw) of frame {worst} has norm "
            f"{norms[worst]:.4f}, not 1; is the layout xyz + xyzw + joints?"
        )
    joints = rows[:, 7:]
    check_radians(joints, g1.JOINT_NAMES, source)  # degrees first: they break every limit
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


def check_radians(joint_pos: np.ndarray, names: tuple[str, ...] | None, label: str) -> None:
    """Reject joint angles (T, J) beyond 2 pi: no G1 joint turns that far, degrees do (the
    words of every clip reader, ``train --reference`` included)."""
    over = np.abs(np.nan_to_num(joint_pos)) > 2 * np.pi
    if over.any():
        row, j = (int(i) for i in np.argwhere(over)[0])
        joint = f"joint '{names[j]}'" if names is not None else f"joint column {j}"
        raise ClipError(
            f"{label}: {joint} = {joint_pos[row, j]:.1f} at frame {row} is beyond 2 pi rad: the "
            "angles look like degrees; convert them to radians."
        )


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
    import pinocchio as pin

    robot = _robot(robot)
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
    import pinocchio as pin

    robot = _robot(robot)
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


class ClipPlausibilityWarning(UserWarning):
    """A clip loads but looks implausible as a physical motion (see :func:`clip_plausibility`)."""


def despike(rows: np.ndarray, threshold: float = 0.02) -> tuple[np.ndarray, int]:
    """Replace single-frame outliers of the base position and joints (rows (T, 36)).

    Per column (base xyz [m], joints [rad]; the quaternion is left alone): a sample further than
    ``threshold`` from its neighbours' mean, and more than 4 x the median such deviation of its
    9-frame window (the motion's own curvature), is replaced by that mean. Retargeting produces
    such one-frame glitches (a foot snapped through the floor); a spline would spread them over
    several frames of acceleration. Returns the cleaned rows and the number of replaced samples.
    """
    out = np.array(rows, dtype=float, copy=True)
    if out.shape[0] < 9:
        return out, 0
    cols = np.r_[0:3, 7 : out.shape[1]]
    x = out[:, cols]
    pad = np.pad(x, ((1, 1), (0, 0)), mode="edge")
    mean_nb = 0.5 * (pad[:-2] + pad[2:])
    dev = np.abs(x - mean_nb)  # half the second difference: curvature of the motion
    pad_dev = np.pad(dev, ((4, 4), (0, 0)), mode="edge")
    typical = np.median(np.stack([pad_dev[k : k + x.shape[0]] for k in range(9)]), axis=0)
    # A spike stands out from the motion's own curvature around it (fast limbs curve a lot).
    peak = np.ones_like(dev, dtype=bool)
    peak[1:] &= dev[1:] > dev[:-1]
    peak[:-1] &= dev[:-1] > dev[1:]  # a spike's neighbours deviate by half as much
    spike = (dev > threshold) & (dev > 4.0 * typical) & peak
    spike[[0, -1]] = False
    x[spike] = mean_nb[spike]
    out[:, cols] = x
    return out, int(spike.sum())


def estimate_ground_m(heights_m: np.ndarray, percentile: float = 5.0) -> float:
    """Floor height [m] from the lowest sole corner per frame and sole (T, 2).

    A low percentile of the per-frame lowest sole, not the single lowest corner: retargeted clips
    sink a foot through the floor for a frame or two, and one such outlier would lift the whole clip
    (every planted sole then hovers and reads as flying).
    """
    return float(np.percentile(np.min(heights_m, axis=1), percentile))


def _hysteresis(enter: np.ndarray, stay: np.ndarray) -> np.ndarray:
    """(T, S) bool: on where ``enter``; stays on while ``stay``; off otherwise."""
    out = np.zeros_like(enter)
    state = enter[0].copy()
    for t in range(enter.shape[0]):
        state = np.where(state, stay[t], enter[t])
        out[t] = state
    return out


def infer_contacts(
    q: np.ndarray,
    dt: float,
    height_m: float = 0.04,
    speed_m_s: float = 0.4,
    robot: G1Pinocchio | None = None,
    release_height_m: float | None = None,
    release_speed_m_s: float | None = None,
    ground_m: float = 0.0,
    support_fallback: bool = True,
    ballistic_accel_m_s2: float = 5.0,
    support_fallback_height_m: float = 0.15,
) -> np.ndarray:
    """Sole contacts (T, 2) bool [left, right] with hysteresis on height and horizontal speed.

    A sole enters contact when its lowest corner is at most ``height_m`` above ``ground_m`` and its
    centre moves at most ``speed_m_s`` horizontally [m/s]; it stays in contact until it is higher
    than ``release_height_m`` or faster than ``release_speed_m_s`` (defaults: 1.75 x and 2 x the
    entry thresholds). With ``support_fallback``, a frame with no sole down whose base is not in
    free fall (vertical base acceleration above ``-ballistic_accel_m_s2``) gets its lower sole in
    contact when that sole is slower than the release speed and at most
    ``support_fallback_height_m`` high: a robot that is not falling is supported. Single-frame flickers are removed last.
    """
    release_height_m = 1.75 * height_m if release_height_m is None else release_height_m
    release_speed_m_s = 2.0 * speed_m_s if release_speed_m_s is None else release_speed_m_s
    heights, origins = sole_corner_heights_m(q, robot)
    heights = heights - ground_m
    speed = np.linalg.norm(np.gradient(origins[..., :2], dt, axis=0), axis=-1)
    enter = (heights <= height_m) & (speed <= speed_m_s)
    stay = (heights <= release_height_m) & (speed <= release_speed_m_s)
    contacts = _hysteresis(enter, stay)
    if support_fallback and q.shape[0] >= 3:
        base_acc_z = np.gradient(np.gradient(q[:, 2], dt), dt)
        lower = np.argmin(heights, axis=1)
        rows = np.arange(q.shape[0])
        fix = (
            ~contacts.any(axis=1)
            & (base_acc_z > -ballistic_accel_m_s2)
            & (speed[rows, lower] <= release_speed_m_s)
            & (heights[rows, lower] <= support_fallback_height_m)
        )
        contacts[rows[fix], lower[fix]] = True
    if contacts.shape[0] >= 3:
        same = contacts[:-2] == contacts[2:]
        middle = contacts[1:-1]
        middle[same] = contacts[:-2][same]
    return contacts


def clip_plausibility(
    contacts: np.ndarray,
    base_rows_w: np.ndarray,
    fps: float,
    ground_m: float,
    lowest_sole_m: np.ndarray,
    despiked_samples: int = 0,
) -> dict:
    """Plausibility figures of a clip (JSON-ready; the oracle adds ``unaided_share_alpha_1``).

    Args:
        contacts: (T, 2) bool sole contacts of the reference.
        base_rows_w: (T0, 3) base positions of the source clip [m].
        fps: source frame rate [1/s].
        ground_m: the floor estimate the clip was shifted by [m].
        lowest_sole_m: (T,) lowest sole corner per frame after the shift [m].
        despiked_samples: samples replaced by :func:`despike`.
    """
    jumps = np.linalg.norm(np.diff(base_rows_w, axis=0), axis=1)
    k = int(np.argmax(jumps)) if jumps.size else 0
    return {
        "no_contact_share": float(np.mean(~contacts.any(axis=1))),
        "double_contact_share": float(np.mean(contacts.all(axis=1))),
        "largest_base_jump_m": float(jumps[k]) if jumps.size else 0.0,
        "largest_base_jump_frame": k,
        "largest_base_speed_m_s": float(jumps[k] * fps) if jumps.size else 0.0,
        "ground_estimate_m": float(ground_m),
        "lowest_sole_percentiles_m": {
            f"p{p}": float(np.percentile(lowest_sole_m, p)) for p in (1, 5, 50, 95, 99)
        },
        "despiked_samples": int(despiked_samples),
    }


def plausibility_problems(report: dict, cfg: ClipConfig = ClipConfig()) -> list[str]:
    """Human-readable problems of a plausibility report (empty: plausible)."""
    problems = []
    share = report["no_contact_share"]
    if share > cfg.warn_no_contact_share:
        problems.append(
            f"{100 * share:.0f} % of the frames have no sole in contact (more than "
            f"{100 * cfg.warn_no_contact_share:.0f} %): the pelvis would carry a flying robot; "
            "check the ground height, the units and the contact thresholds (--clip-contact-*)"
        )
    unaided = report.get("unaided_share_alpha_1")
    if unaided is not None and unaided < 0.5:
        problems.append(
            f"only {100 * unaided:.0f} % of the frames are doable unaided at alpha = 1: the clip "
            "is far from physically consistent for the G1"
        )
    return problems


def reference_from_configurations(
    q: np.ndarray,
    dt: float,
    cfg: ClipConfig = ClipConfig(),
    name: str = "clip",
    phase_names: tuple[str, ...] = ("dance",),
    contacts: np.ndarray | None = None,
    robot: G1Pinocchio | None = None,
) -> Reference:
    """Reference from configurations (T, 36) at step ``dt``: ground, differentiate, contacts.

    With ``cfg.ground_to_lowest_sole`` the clip is shifted so that the robust ground estimate
    (:func:`estimate_ground_m`) is at z = 0. ``extras["lowest_sole_m"]`` (T,) holds the lowest sole
    corner per frame after the shift [m].
    """
    robot = _robot(robot)
    q = np.array(q, dtype=float)
    heights, _ = sole_corner_heights_m(q, robot)
    if cfg.ground_to_lowest_sole:
        ground = estimate_ground_m(heights, cfg.ground_percentile)
        q[:, 2] -= ground
        heights = heights - ground
    v, a = differentiate(q, dt, cfg.smoothing_window_s, cfg.polyorder, robot)
    if contacts is None:
        contacts = infer_contacts(
            q,
            dt,
            cfg.contact_height_m,
            cfg.contact_speed_m_s,
            robot,
            release_height_m=cfg.contact_release_height_m,
            release_speed_m_s=cfg.contact_release_speed_m_s,
            support_fallback=cfg.support_fallback,
            ballistic_accel_m_s2=cfg.ballistic_accel_m_s2,
            support_fallback_height_m=cfg.support_fallback_height_m,
        )
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


def load_motion_clip_with_report(
    path: str | Path, cfg: ClipConfig = ClipConfig(), name: str = "dance"
) -> tuple[Reference, dict]:
    """Like :func:`load_motion_clip`, and the plausibility report (:func:`clip_plausibility`).

    Raises :class:`ClipError` when more than ``cfg.max_no_contact_share`` of the frames have no
    sole in contact; warns (:class:`ClipPlausibilityWarning`) above ``cfg.warn_no_contact_share``.
    """
    rows, fps = read_clip(path, cfg)
    return reference_from_clip_rows(rows, fps, cfg, name, source=f"Motion clip '{path}'")


def reference_from_clip_rows(
    rows: np.ndarray,
    fps: float,
    cfg: ClipConfig = ClipConfig(),
    name: str = "dance",
    source: str = "clip",
    phase_names: tuple[str, ...] = ("dance",),
    robot: G1Pinocchio | None = None,
) -> tuple[Reference, dict]:
    """Raw clip rows (T, 36) at ``fps`` [1/s] to a one-phase reference and its plausibility report.

    The pipeline of :func:`load_motion_clip_with_report` after reading the file (validate, despike,
    resample to ``cfg.target_fps``, ground, differentiate, contacts, plausibility), for callers
    that read other layouts; ``source`` names the input in error messages.
    """
    robot = _robot(robot)
    rows = validate_clip(rows, fps, cfg, robot, source=source)
    replaced = 0
    if cfg.despike:
        rows, replaced = despike(rows, cfg.despike_threshold_m)
        rows[:, 3:7] /= np.linalg.norm(rows[:, 3:7], axis=1, keepdims=True)
    q = resample(rows, fps, cfg.target_fps)
    if cfg.max_frames > 0:
        q = q[: cfg.max_frames]
    ref = reference_from_configurations(
        q, 1.0 / cfg.target_fps, cfg, name=name, phase_names=phase_names, robot=robot
    )
    heights, _ = sole_corner_heights_m(ref.q, robot)
    raw_heights, _ = sole_corner_heights_m(q, robot)
    ground = float(np.min(raw_heights) - np.min(heights)) if cfg.ground_to_lowest_sole else 0.0
    report = clip_plausibility(
        ref.contacts, rows[:, :3], fps, ground, heights.min(axis=1), replaced
    )
    share = report["no_contact_share"]
    if share > cfg.max_no_contact_share:
        raise ClipError(
            f"{source}: {100 * share:.0f} % of the frames have no sole in contact (at most "
            f"{100 * cfg.max_no_contact_share:.0f} % allowed, --clip-max-no-contact-share): the "
            "pelvis would have to carry the robot. Check that positions are in metres, z is up, "
            "and the contact thresholds (--clip-contact-height-m) suit the clip."
        )
    for problem in plausibility_problems(report, cfg):
        warnings.warn(f"{source}: {problem}", ClipPlausibilityWarning, stacklevel=3)
    return ref, report


def load_motion_clip(
    path: str | Path, cfg: ClipConfig = ClipConfig(), name: str = "dance"
) -> Reference:
    """Load, validate, despike, resample and differentiate a clip file into a one-phase reference.

    See :func:`load_motion_clip_with_report` for the plausibility checks it runs.
    """
    return load_motion_clip_with_report(path, cfg, name)[0]
