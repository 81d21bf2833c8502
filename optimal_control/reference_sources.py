"""One loader for every motion reference a user can hand the tracking trainer (``--reference``).

:func:`load_reference` turns any of these into a :class:`~optimal_control.reference.Reference` in
Pinocchio layout (q = [p_w, quat xyzw, 29 joints in :data:`robots.g1.JOINTS` order]):

* **LAFAN1 G1 CSV** (no header, 36 columns: base xyz [m], quaternion xyzw, 29 joints [rad] in URDF
  order; ``ClipConfig.source_fps``, 30 fps) and **our NPZ clip** (``qpos`` or ``root_pos`` +
  ``root_quat_xyzw`` + ``joint_pos``, optional ``fps``): read by
  :func:`optimal_control.motion_clip.read_clip`.
* **whole_body_tracking (BeyondMimic) / mjlab motion NPZ**, as their ``scripts/csv_to_npz.py``
  writes it: ``fps`` (shape (1,)), ``joint_pos`` (T, 29), ``joint_vel`` (T, 29), ``body_pos_w``
  (T, B, 3), ``body_quat_w`` (T, B, 4, w x y z), ``body_lin_vel_w``, ``body_ang_vel_w`` (T, B, 3),
  world frame, usually 50 fps. Body 0 is the pelvis (the articulation's root link in Isaac Lab and
  mjlab alike), so its pose is the base; the velocities are not read (they are recomputed from the
  poses like for every other source). The joint order is the simulator's:
  Isaac Lab (whole_body_tracking) orders the G1's joints breadth-first
  (:data:`ISAACLAB_G1_JOINT_NAMES`: left/right hip pitch, waist yaw, ...), mjlab writes MuJoCo's
  order, which is the URDF order. Neither file says which; see :func:`wbt_joint_order`.
* **An oracle artifact folder** (``a2cf-mb solve-walk``, ``solve-dance``, ``solve-backflip``): the
  reference stored in its ``arrays.npz`` with its phases and contacts, at the artifact's own step
  (50 Hz; a backflip's step may be slightly finer, its last frame being the landed pose).

Clips (the first three) go through the pipeline of
:func:`optimal_control.motion_clip.reference_from_clip_rows`: validation, despiking, resampling to
``ClipConfig.target_fps`` (50 Hz; cubic splines, slerp), ground shift, differentiation, contacts,
plausibility; they come back with one phase, :data:`TRACK_PHASE`.

``frames = (A, B)`` keeps source frames A (inclusive) to B (exclusive) in the source's own frame
numbering (a 30 fps CSV: 0:600 is its first 20 s; an artifact: its own frames), before
resampling. Every bad input raises one :class:`~optimal_control.motion_clip.ClipError` line naming
the input, what is wrong and what to do.
"""

from __future__ import annotations

import hashlib
import re
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from optimal_control.files import read_npz
from optimal_control.motion_clip import (
    ClipConfig,
    ClipError,
    check_radians,
    read_clip,
    reference_from_clip_rows,
)
from optimal_control.reference import NQ, Reference
from robots import g1
from robots.conventions import quat_wxyz_to_xyzw

if TYPE_CHECKING:
    from robots.pinocchio_model import G1Pinocchio

TRACK_PHASE = "track"
"""Name of the single phase of a reference loaded from a clip file."""

MIN_DURATION_S = 1.0
"""Shortest reference, after the segment, :func:`load_reference` accepts [s]."""

FRAMES_FLAG = "--reference-frames"
"""The CLI flag whose text :func:`parse_frames` reads."""

CLIP_FRAMES_FLAG = "--clip-frames"
"""``solve-dance``'s segment flag (the same syntax as :data:`FRAMES_FLAG`)."""

ISAACLAB_G1_JOINT_NAMES: tuple[str, ...] = (
    "left_hip_pitch_joint",
    "right_hip_pitch_joint",
    "waist_yaw_joint",
    "left_hip_roll_joint",
    "right_hip_roll_joint",
    "waist_roll_joint",
    "left_hip_yaw_joint",
    "right_hip_yaw_joint",
    "waist_pitch_joint",
    "left_knee_joint",
    "right_knee_joint",
    "left_shoulder_pitch_joint",
    "right_shoulder_pitch_joint",
    "left_ankle_pitch_joint",
    "right_ankle_pitch_joint",
    "left_shoulder_roll_joint",
    "right_shoulder_roll_joint",
    "left_ankle_roll_joint",
    "right_ankle_roll_joint",
    "left_shoulder_yaw_joint",
    "right_shoulder_yaw_joint",
    "left_elbow_joint",
    "right_elbow_joint",
    "left_wrist_roll_joint",
    "right_wrist_roll_joint",
    "left_wrist_pitch_joint",
    "right_wrist_pitch_joint",
    "left_wrist_yaw_joint",
    "right_wrist_yaw_joint",
)
"""The G1's 29 joints in Isaac Lab's articulation order (breadth-first over the kinematic tree),
the order of ``joint_pos`` in a whole_body_tracking motion NPZ."""

JOINT_ORDERS: dict[str, tuple[str, ...]] = {
    "urdf": g1.JOINT_NAMES,  # URDF = MuJoCo = mjlab = LAFAN1 CSV order
    "isaaclab": ISAACLAB_G1_JOINT_NAMES,  # whole_body_tracking (Isaac Lab)
}
"""Joint orders a motion NPZ without ``joint_names`` may be in (``joint_order`` argument)."""

WBT_REQUIRED_KEYS = ("fps", "joint_pos", "body_pos_w", "body_quat_w")
"""Arrays of a whole_body_tracking / mjlab motion NPZ that :func:`load_reference` reads."""

BODY_MATCH_TOLERANCE_M = 0.02
"""Mean distance from each stored body to the nearest link of our G1 at which a joint order
explains the stored body positions [m]."""

_FINGERPRINT_DECIMALS = 5  # q rounded to 1e-5 m / rad: float noise of a re-save does not count


def parse_frames(text: str, flag: str = FRAMES_FLAG) -> tuple[int, int] | None:
    """``"A:B"`` -> ``(A, B)`` (source frames A inclusive to B exclusive); ``""`` -> None.

    Raises:
        ValueError: naming ``flag`` (the flag the text came from) and the expected form.
    """
    text = text.strip()
    if not text:
        return None
    match = re.fullmatch(r"(\d+)\s*:\s*(\d+)", text)
    if match is None or int(match[1]) >= int(match[2]):
        raise ValueError(
            f"{flag} '{text}': expected START:STOP, two whole numbers with START < STOP "
            "(source frames, START inclusive, STOP exclusive; e.g. 0:600 for the first 20 s of a "
            "30 fps CSV), or nothing for the whole reference."
        )
    return int(match[1]), int(match[2])


def reference_fingerprint(ref: Reference) -> str:
    """A short stable hash (16 hex digits) of a reference's motion: q rounded to 1e-5, and dt.

    The quaternion sign is made canonical (w >= 0) first, so q and -q hash alike; contacts, phases
    and names do not count. Equal fingerprints: an artifact was made from the task's motion.
    """
    q = np.array(ref.q, dtype=float)
    q[q[:, 6] < 0, 3:7] *= -1.0
    digits = np.rint(q * 10**_FINGERPRINT_DECIMALS).astype("<i8")
    digest = hashlib.sha256(f"{q.shape}|dt={round(float(ref.dt), 9)!r}|".encode())
    digest.update(np.ascontiguousarray(digits).tobytes())
    return digest.hexdigest()[:16]


def load_reference(
    source: str | Path,
    frames: tuple[int, int] | None = None,
    name: str | None = None,
    cfg: ClipConfig = ClipConfig(),
    joint_order: str = "auto",
    min_duration_s: float = MIN_DURATION_S,
) -> Reference:
    """The reference of a clip file or an oracle artifact folder (formats in the module docstring).

    Args:
        source: a ``.csv`` / ``.npz`` clip or an artifact folder.
        frames: ``(A, B)``: source frames A (inclusive) to B (exclusive), before resampling; None:
            all.
        name: the reference's name; default: the file's stem, or the artifact reference's name.
        cfg: how a clip becomes a reference (source frame rate of a CSV, 50 Hz target, contacts).
        joint_order: joint order of a whole_body_tracking / mjlab NPZ without ``joint_names``:
            ``"auto"`` (the order whose forward kinematics reproduces the stored body positions,
            :func:`wbt_joint_order`), ``"isaaclab"`` (whole_body_tracking) or ``"urdf"`` (mjlab).
            Other sources ignore it.
        min_duration_s: shortest reference after the segment [s].

    Returns:
        A validated reference: a clip's at ``cfg.target_fps`` with one phase (:data:`TRACK_PHASE`),
        an artifact's at its own step with its phases.

    Raises:
        ClipError: one line naming the input, what is wrong and what to do.
    """
    path = Path(source)
    label = f"Reference '{path}'"
    if joint_order not in ("auto", *JOINT_ORDERS):
        raise ClipError(
            f"{label}: joint_order '{joint_order}' is unknown; use 'auto', "
            + ", ".join(f"'{k}'" for k in JOINT_ORDERS)
            + "."
        )
    if frames is not None:
        frames = _check_frames_form(frames, label)
    if path.is_dir():
        return _artifact_reference(path, frames, name, min_duration_s, label)
    rows, fps = read_clip_segment(path, frames, cfg, joint_order, min_duration_s)
    ref, _ = reference_from_clip_rows(
        rows, fps, cfg, name or path.stem, source=label, phase_names=(TRACK_PHASE,)
    )
    return ref


def read_clip_segment(
    path: str | Path,
    frames: tuple[int, int] | None,
    cfg: ClipConfig = ClipConfig(),
    joint_order: str = "auto",
    min_duration_s: float = MIN_DURATION_S,
    flag: str = FRAMES_FLAG,
) -> tuple[np.ndarray, float]:
    """Rows (T, 36) in our layout and the frame rate [1/s] of frames ``[A, B)`` of a clip file
    (LAFAN1 G1 CSV, our NPZ, a whole_body_tracking / mjlab NPZ): the segment and the checks of
    :func:`load_reference`, before the clip pipeline; ``flag`` names the segment's flag in errors.

    Raises:
        ClipError: one line naming the input, what is wrong and what to do.
    """
    path = Path(path)
    label = f"Reference '{path}'"
    if frames is not None:
        frames = _check_frames_form(frames, label, flag)
    if not path.is_file():
        raise ClipError(
            f"{label} does not exist (or is not a file); check --reference: a .csv / .npz clip or "
            "an oracle artifact folder."
        )
    suffix = path.suffix.lower()
    if suffix == ".npz" and _is_wbt_npz(path):
        rows, fps = _wbt_rows(path, frames, joint_order, label, cfg.quat_norm_tolerance, flag)
    elif suffix in (".csv", ".npz"):
        rows, fps = read_clip(path, cfg)
        rows = _select(np.asarray(rows, dtype=float), frames, fps, label, flag)
    else:
        raise ClipError(
            f"{label}: unknown format '{suffix}'; use a .csv or .npz clip, or an oracle artifact "
            "folder."
        )
    _check_clip_rows(rows, fps, min_duration_s, label, flag)
    return rows, fps


def _check_frames_form(
    frames: tuple[int, int], label: str, flag: str = FRAMES_FLAG
) -> tuple[int, int]:
    try:
        a, b = (int(f) for f in frames)
    except (TypeError, ValueError) as err:
        raise ClipError(f"{label}: frames must be (START, STOP), got {frames!r}.") from err
    if a < 0 or a >= b:
        raise ClipError(
            f"{label}: {flag} {a}:{b} is empty or negative; pick 0 <= START < STOP "
            "(STOP exclusive)."
        )
    return a, b


def _select(
    array: np.ndarray,
    frames: tuple[int, int] | None,
    fps: float,
    label: str,
    flag: str = FRAMES_FLAG,
):
    """Frames ``[A, B)`` of ``array`` (T, ...), checked against its T frames."""
    num = int(array.shape[0]) if array.ndim else 0
    if num == 0:
        raise ClipError(f"{label} has no frames; pass a clip with at least {MIN_DURATION_S:g} s.")
    if frames is None:
        return array
    a, b = frames
    if b > num:
        raise ClipError(
            f"{label}: {flag} {a}:{b} is out of range: the source has {num} frames at "
            f"{fps:g} fps (0:{num} is all of it); pick STOP <= {num}."
        )
    return array[a:b]


def _check_clip_rows(
    rows: np.ndarray, fps: float, min_duration_s: float, label: str, flag: str = FRAMES_FLAG
) -> None:
    """Layout, length and angle units of clip rows (T, 36); the rest is ``validate_clip``'s."""
    if rows.ndim != 2 or rows.shape[1] != NQ:
        raise ClipError(
            f"{label}: frames of shape {rows.shape[1:]}, expected {NQ} columns (base xyz [m], "
            f"quaternion xyzw, {g1.NUM_JOINTS} joint angles [rad] in URDF order, like the LAFAN1 "
            "G1 CSV)."
        )
    bad = ~np.isfinite(rows)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise ClipError(
            f"{label}: NaN/inf at frame {row}, column {col}; repair the clip or leave those "
            f"frames out with {flag}."
        )
    span_s = (rows.shape[0] - 1) / fps if np.isfinite(fps) and fps > 0 else np.inf
    if span_s < min_duration_s:
        raise ClipError(
            f"{label}: the reference lasts {span_s:.2f} s ({rows.shape[0]} frames at {fps:g} fps), "
            f"shorter than {min_duration_s:g} s; give a longer clip or a wider {flag}."
        )
    check_radians(rows[:, 7:], g1.JOINT_NAMES, label)


# --- whole_body_tracking / mjlab motion NPZ ---------------------------------------------------


def _is_wbt_npz(path: Path) -> bool:
    """True when the archive holds body poses (the whole_body_tracking / mjlab layout)."""
    if not zipfile.is_zipfile(path):
        return False  # junk: read_clip says so
    try:
        with zipfile.ZipFile(path) as archive:
            keys = {Path(n).stem for n in archive.namelist()}
    except (zipfile.BadZipFile, OSError):
        return False  # truncated: read_clip says so
    return bool(keys & {"body_pos_w", "body_quat_w"})


def _wbt_rows(
    path: Path,
    frames: tuple[int, int] | None,
    joint_order: str,
    label: str,
    quat_norm_tolerance: float = ClipConfig.quat_norm_tolerance,
    flag: str = FRAMES_FLAG,
) -> tuple[np.ndarray, float]:
    """Clip rows (T, 36) in our layout and the frame rate of a whole_body_tracking / mjlab NPZ."""
    try:
        npz = read_npz(path, "Reference")
    except ValueError as err:
        raise ClipError(str(err)) from err
    missing = [k for k in WBT_REQUIRED_KEYS if k not in npz]
    if missing:
        raise ClipError(
            f"{label} looks like a whole_body_tracking / mjlab motion (it has body poses) but lacks "
            f"{missing}; it needs {list(WBT_REQUIRED_KEYS)} as csv_to_npz.py writes them: "
            "regenerate it."
        )
    fps_arr = npz["fps"]
    if fps_arr.size != 1 or not np.issubdtype(fps_arr.dtype, np.number):
        raise ClipError(
            f"{label}: 'fps' must be one number (frames per second), got shape {fps_arr.shape} "
            f"and dtype {fps_arr.dtype}."
        )
    fps = float(fps_arr.reshape(()))
    if not (np.isfinite(fps) and fps > 0):
        raise ClipError(f"{label}: 'fps' must be a finite number > 0, got {fps}.")
    joint_pos = np.asarray(npz["joint_pos"], dtype=float)
    pos = np.asarray(npz["body_pos_w"], dtype=float)
    quat = np.asarray(npz["body_quat_w"], dtype=float)
    for key, arr, tail in (("joint_pos", joint_pos, None), ("body_pos_w", pos, 3)):
        if (tail is None and arr.ndim != 2) or (tail is not None and arr.shape[2:] != (tail,)):
            want = "(T, joints)" if tail is None else f"(T, bodies, {tail})"
            raise ClipError(f"{label}: '{key}' has shape {arr.shape}, expected {want}.")
    if quat.ndim != 3 or quat.shape[2] != 4 or quat.shape[:2] != pos.shape[:2]:
        raise ClipError(
            f"{label}: 'body_quat_w' has shape {quat.shape}, expected (T, bodies, 4) = "
            f"{(*pos.shape[:2], 4)} like 'body_pos_w'."
        )
    if joint_pos.shape[0] != pos.shape[0]:
        raise ClipError(
            f"{label}: 'joint_pos' has {joint_pos.shape[0]} frames but 'body_pos_w' has "
            f"{pos.shape[0]}; the arrays must cover the same frames."
        )
    names = _stored_joint_names(npz, joint_pos.shape[1], label)
    joint_pos = _select(joint_pos, frames, fps, label, flag)
    pos = _select(pos, frames, fps, label, flag)
    quat = _select(quat, frames, fps, label, flag)
    for key, arr in (("joint_pos", joint_pos), ("body_pos_w", pos), ("body_quat_w", quat)):
        bad = ~np.isfinite(arr.reshape(arr.shape[0], -1))
        if bad.any():
            raise ClipError(
                f"{label}: '{key}' has NaN/inf (first at frame {int(np.argwhere(bad)[0, 0])}); "
                "fix or re-export the motion."
            )
    base = np.concatenate([pos[:, 0], quat_wxyz_to_xyzw(quat[:, 0])], axis=1)  # body 0: pelvis
    norms = np.linalg.norm(base[:, 3:7], axis=1)
    worst = int(np.argmax(np.abs(norms - 1.0)))
    if abs(norms[worst] - 1.0) > quat_norm_tolerance:
        raise ClipError(
            f"{label}: 'body_quat_w' of body 0 (the pelvis) at frame {worst} has norm "
            f"{norms[worst]:.4f}, not 1; quaternions must be unit, w x y z."
        )
    check_radians(joint_pos, names, label)
    if names is None:
        if joint_pos.shape[1] != g1.NUM_JOINTS:
            raise ClipError(
                f"{label}: 'joint_pos' has {joint_pos.shape[1]} columns, expected the G1's "
                f"{g1.NUM_JOINTS} (or a 'joint_names' array naming each column)."
            )
        if joint_order == "auto":
            joint_order = wbt_joint_order(base, joint_pos, pos, label)
        names = JOINT_ORDERS[joint_order]
    column = {n: i for i, n in enumerate(names)}
    joints_urdf = joint_pos[:, [column[n] for n in g1.JOINT_NAMES]]
    return np.concatenate([base, joints_urdf], axis=1), fps


def _stored_joint_names(npz: dict, num_cols: int, label: str) -> tuple[str, ...] | None:
    """The file's ``joint_names`` (one per ``joint_pos`` column, all G1 joints among them)."""
    if "joint_names" not in npz:
        return None
    names = tuple(str(n) for n in np.asarray(npz["joint_names"]).reshape(-1))
    if len(names) != num_cols:
        raise ClipError(
            f"{label}: 'joint_names' has {len(names)} names for {num_cols} 'joint_pos' columns."
        )
    lacking = [n for n in g1.JOINT_NAMES if n not in names]
    if lacking:
        raise ClipError(
            f"{label}: 'joint_names' lacks the G1 joints {lacking}; is it a 29-DoF G1 motion?"
        )
    return names


def wbt_joint_order(
    base_q: np.ndarray,
    joint_pos: np.ndarray,
    body_pos_w: np.ndarray,
    label: str = "motion",
    robot: G1Pinocchio | None = None,
    num_samples: int = 5,
) -> str:
    """The key of :data:`JOINT_ORDERS` whose forward kinematics reproduces the stored bodies.

    For a few frames, our G1 is posed at the stored pelvis pose ``base_q`` (T, 7: xyz, quat xyzw)
    with ``joint_pos`` (T, 29) read in each candidate order; each stored body (``body_pos_w``
    (T, B, 3), in whatever body order) is matched to the nearest link of ours. The order whose mean
    distance is below :data:`BODY_MATCH_TOLERANCE_M` wins (the URDF order when both do, which
    happens only when the two readings give one pose). Raises :class:`ClipError` when no order
    explains the bodies (another robot, the pelvis not body 0, or a quaternion not w x y z).
    """
    if body_pos_w.shape[1] < 2:
        raise ClipError(
            f"{label}: the joint order cannot be told from a pelvis alone (no other bodies in "
            "'body_pos_w'); pass joint_order='isaaclab' (whole_body_tracking) or 'urdf' (mjlab)."
        )
    import pinocchio as pin  # here: loading an artifact needs no Pinocchio

    from robots.pinocchio_model import build_pinocchio_model

    robot = robot or build_pinocchio_model()
    data = robot.data()
    links = [f for f, frame in enumerate(robot.model.frames) if frame.type == pin.BODY]
    picks = np.unique(np.linspace(0, joint_pos.shape[0] - 1, num_samples).round().astype(int))
    errors = {}
    for key, names in JOINT_ORDERS.items():
        column = {n: i for i, n in enumerate(names)}
        perm = [column[n] for n in g1.JOINT_NAMES]
        dist = []
        for t in picks:
            q = robot.configuration(joint_pos[t, perm], base_q[t, :3], base_q[t, 3:7])
            q[3:7] /= np.linalg.norm(q[3:7])
            pin.framesForwardKinematics(robot.model, data, q)
            ours = np.array([data.oMf[f].translation for f in links])  # (L, 3)
            gap = np.linalg.norm(body_pos_w[t][:, None, :] - ours[None], axis=-1)  # (B, L)
            dist.append(gap.min(axis=1))
        errors[key] = float(np.mean(dist))
    fits = [k for k, e in errors.items() if e <= BODY_MATCH_TOLERANCE_M]
    if not fits:
        found = ", ".join(f"{k}: {100 * e:.1f} cm" for k, e in errors.items())
        raise ClipError(
            f"{label}: no joint order reproduces the stored body positions (mean distance to our "
            f"G1's links {found}; at most {100 * BODY_MATCH_TOLERANCE_M:g} cm expected). Is it a "
            "29-DoF G1 motion with the pelvis as body 0 and w x y z quaternions? Pass "
            "joint_order='isaaclab' or 'urdf' to skip the check."
        )
    return "urdf" if "urdf" in fits else min(fits, key=errors.__getitem__)


# --- oracle artifact ------------------------------------------------------------------------


def _artifact_reference(
    folder: Path,
    frames: tuple[int, int] | None,
    name: str | None,
    min_duration_s: float,
    label: str,
) -> Reference:
    """The reference of an artifact folder, its phases kept, frames ``[A, B)`` of its own."""
    # Imported here: the artifact module brings the wrench QP, which clip users never need.
    from optimal_control.artifact import SUMMARY_FILE, OracleArtifact

    if not (folder / SUMMARY_FILE).is_file():
        raise ClipError(
            f"{label} is a folder but not an oracle artifact ({SUMMARY_FILE} is missing); pass a "
            ".csv / .npz clip or a folder written by `a2cf-mb solve-walk`, `solve-dance` or "
            "`solve-backflip`."
        )
    try:
        ref = OracleArtifact.load(folder).reference
    except ValueError as err:  # ArtifactError, ReferenceError, an unreadable arrays.npz
        raise ClipError(f"{label}: {err}") from err
    if frames is not None:
        a, b = frames
        if b > ref.num_frames:
            raise ClipError(
                f"{label}: {FRAMES_FLAG} {a}:{b} is out of range: the artifact's reference has "
                f"{ref.num_frames} frames (0:{ref.num_frames} is all of it); pick STOP <= "
                f"{ref.num_frames}."
            )
        ref = ref.slice(a, b)
    if ref.duration_s < min_duration_s:
        raise ClipError(
            f"{label}: the reference lasts {ref.duration_s:.2f} s ({ref.num_frames} frames), "
            f"shorter than {min_duration_s:g} s; give a wider {FRAMES_FLAG} or another artifact."
        )
    if name:
        ref.name = name
    return ref
