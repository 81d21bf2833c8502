"""Reference sources: CSV, our NPZ, whole_body_tracking / mjlab NPZ and artifacts load alike;
segments; fingerprints; every bad input is one error line naming it."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pinocchio as pin
import pytest

from optimal_control.artifact import OracleArtifact, build_artifact
from optimal_control.bounds import BoundRule
from optimal_control.motion_clip import ClipError, reference_from_clip_rows
from optimal_control.reference import NV, Reference
from optimal_control.reference_sources import (
    ISAACLAB_G1_JOINT_NAMES,
    TRACK_PHASE,
    load_reference,
    parse_frames,
    reference_fingerprint,
)
from optimal_control.wrench_qp import WrenchProfile
from robots import g1

FPS = 30.0
KNEE = g1.JOINT_NAMES.index("left_knee_joint")
SHOULDER = g1.JOINT_NAMES.index("right_shoulder_pitch_joint")
HIP_ROLL = g1.JOINT_NAMES.index("right_hip_roll_joint")

# The G1 in Isaac Lab's articulation order (breadth-first), as whole_body_tracking's csv_to_npz.py
# stores joint_pos, written out here independently of the module under test.
ISAAC_JOINTS = (
    *("left_hip_pitch_joint", "right_hip_pitch_joint", "waist_yaw_joint"),
    *("left_hip_roll_joint", "right_hip_roll_joint", "waist_roll_joint"),
    *("left_hip_yaw_joint", "right_hip_yaw_joint", "waist_pitch_joint"),
    *("left_knee_joint", "right_knee_joint"),
    *("left_shoulder_pitch_joint", "right_shoulder_pitch_joint"),
    *("left_ankle_pitch_joint", "right_ankle_pitch_joint"),
    *("left_shoulder_roll_joint", "right_shoulder_roll_joint"),
    *("left_ankle_roll_joint", "right_ankle_roll_joint"),
    *("left_shoulder_yaw_joint", "right_shoulder_yaw_joint"),
    *("left_elbow_joint", "right_elbow_joint"),
    *("left_wrist_roll_joint", "right_wrist_roll_joint"),
    *("left_wrist_pitch_joint", "right_wrist_pitch_joint"),
    *("left_wrist_yaw_joint", "right_wrist_yaw_joint"),
)


def _link(joint: str) -> str:
    """URDF child link of a G1 joint."""
    return "torso_link" if joint == "waist_pitch_joint" else joint.replace("_joint", "_link")


# Bodies of each producer: the pelvis first (both simulators list the root link first), then the
# joints' links roughly in the simulator's order; the loader does not depend on that order.
MJLAB_BODIES = ["pelvis"] + [_link(j) for j in g1.JOINT_NAMES]
ISAAC_BODIES = ["pelvis"] + [_link(j) for j in ISAAC_JOINTS]


def clip_rows(robot, times: np.ndarray) -> np.ndarray:
    """Rows (T, 36): the standing pose, base walking forward and yawing, joints waving smoothly."""
    rows = np.tile(robot.q_stand, (times.shape[0], 1))
    rows[:, 0] += 0.3 * times
    yaw = 0.4 * times
    rows[:, 3:7] = np.stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)
    rows[:, 7 + SHOULDER] = 0.2 + 0.5 * np.sin(2.0 * times)
    rows[:, 7 + KNEE] = 0.669 + 0.1 * np.sin(2.0 * times)
    rows[:, 7 + HIP_ROLL] = 0.1 * np.sin(3.0 * times)
    return rows


def wbt_arrays(robot, rows: np.ndarray, fps: float, producer: str) -> dict[str, np.ndarray]:
    """A motion NPZ as whole_body_tracking ("isaac") or mjlab ("mjlab") csv_to_npz.py writes it:
    float32, joints in the simulator's order, body link poses (quaternions w x y z) by Pinocchio
    forward kinematics, zero velocities (the loader recomputes them), fps of shape (1,)."""
    joints, bodies = (g1.JOINT_NAMES, MJLAB_BODIES)
    if producer == "isaac":
        joints, bodies = ISAAC_JOINTS, ISAAC_BODIES
    col = [g1.JOINT_NAMES.index(n) for n in joints]
    data = robot.data()
    ids = [robot.model.getFrameId(b, pin.BODY) for b in bodies]
    num = rows.shape[0]
    pos = np.zeros((num, len(bodies), 3))
    quat = np.zeros((num, len(bodies), 4))
    for t in range(num):
        pin.framesForwardKinematics(robot.model, data, rows[t])
        for b, i in enumerate(ids):
            pos[t, b] = data.oMf[i].translation
            x, y, z, w = pin.Quaternion(data.oMf[i].rotation).coeffs()
            quat[t, b] = (w, x, y, z)
    zeros = np.zeros_like(pos)
    return {
        "fps": np.array([fps]),
        "joint_pos": rows[:, 7:][:, col].astype(np.float32),
        "joint_vel": np.zeros((num, 29), dtype=np.float32),
        "body_pos_w": pos.astype(np.float32),
        "body_quat_w": quat.astype(np.float32),
        "body_lin_vel_w": zeros.astype(np.float32),
        "body_ang_vel_w": zeros.astype(np.float32),
    }


@pytest.fixture(scope="module")
def rows(g1_pin):
    """A 2 s clip at 30 fps."""
    return clip_rows(g1_pin, np.arange(60) / FPS)


@pytest.fixture(scope="module")
def sources(g1_pin, rows, tmp_path_factory):
    """The clip as a CSV, our NPZ, and whole_body_tracking and mjlab motion NPZs."""
    folder = tmp_path_factory.mktemp("sources")
    np.savetxt(folder / "clip.csv", rows, delimiter=",")
    np.savez(folder / "ours.npz", qpos=rows, fps=FPS)
    np.savez(folder / "wbt.npz", **wbt_arrays(g1_pin, rows, FPS, "isaac"))
    np.savez(folder / "mjlab.npz", **wbt_arrays(g1_pin, rows, FPS, "mjlab"))
    return folder


def test_isaaclab_joint_order_constant():
    assert tuple(ISAAC_JOINTS) == ISAACLAB_G1_JOINT_NAMES
    assert sorted(ISAAC_JOINTS) == sorted(g1.JOINT_NAMES)


def test_every_source_gives_the_same_reference(sources):
    csv = load_reference(sources / "clip.csv")
    assert csv.dt == pytest.approx(0.02)
    assert csv.phase_names == (TRACK_PHASE,)
    assert csv.name == "clip"
    assert csv.num_frames == int(np.floor(59 / FPS * 50 + 1e-9)) + 1
    for name in ("ours.npz", "wbt.npz", "mjlab.npz"):
        ref = load_reference(sources / name)
        assert ref.name == name.removesuffix(".npz")
        assert ref.num_frames == csv.num_frames
        np.testing.assert_allclose(ref.q, csv.q, atol=1e-5, err_msg=name)  # float32 files
    assert load_reference(sources / "clip.csv", name="mine").name == "mine"


def test_wbt_joint_order_explicit_and_named(g1_pin, rows, sources, tmp_path):
    csv = load_reference(sources / "clip.csv")
    isaac = load_reference(sources / "wbt.npz", joint_order="isaaclab")
    np.testing.assert_allclose(isaac.q, csv.q, atol=1e-5)
    mj = load_reference(sources / "mjlab.npz", joint_order="urdf")
    np.testing.assert_allclose(mj.q, csv.q, atol=1e-5)
    # A file that names its columns is read by name, whatever their order.
    arrays = wbt_arrays(g1_pin, rows, FPS, "isaac")
    shuffle = np.random.default_rng(0).permutation(29)
    arrays["joint_pos"] = arrays["joint_pos"][:, shuffle]
    arrays["joint_names"] = np.array(ISAAC_JOINTS)[shuffle]
    np.savez(tmp_path / "named.npz", **arrays)
    np.testing.assert_allclose(load_reference(tmp_path / "named.npz").q, csv.q, atol=1e-5)


def test_wbt_at_50_fps_matches_the_30_fps_csv(g1_pin, sources, tmp_path):
    times = np.arange(int(59 / FPS * 50) + 1) / 50.0
    np.savez(tmp_path / "wbt50.npz", **wbt_arrays(g1_pin, clip_rows(g1_pin, times), 50.0, "isaac"))
    ref = load_reference(tmp_path / "wbt50.npz")
    csv = load_reference(sources / "clip.csv")
    assert ref.num_frames == csv.num_frames
    np.testing.assert_allclose(ref.q[:, 7:], csv.q[:, 7:], atol=2e-3)  # spline of 30 fps samples
    np.testing.assert_allclose(ref.q[:, :3], csv.q[:, :3], atol=1e-3)


def test_segment_selects_source_frames(g1_pin, rows, sources, tmp_path):
    np.savetxt(tmp_path / "part.csv", rows[15:60], delimiter=",")
    part = load_reference(tmp_path / "part.csv")
    for name in ("clip.csv", "ours.npz", "wbt.npz"):
        ref = load_reference(sources / name, frames=(15, 60))
        np.testing.assert_allclose(ref.q, part.q, atol=1e-5, err_msg=name)
    assert part.duration_s == pytest.approx(np.floor(44 / FPS * 50) / 50)


def test_parse_frames():
    assert parse_frames("") is None
    assert parse_frames("  ") is None
    assert parse_frames("0:600") == (0, 600)
    assert parse_frames(" 15 : 60 ") == (15, 60)
    for bad in ("0-600", "10:5", "7:7", "a:b", "5", "-1:4", "1:2:3"):
        with pytest.raises(ValueError, match="--reference-frames .*START:STOP") as err:
            parse_frames(bad)
        assert "\n" not in str(err.value)


def test_fingerprint(g1_pin, rows, sources):
    csv = load_reference(sources / "clip.csv")
    fp = reference_fingerprint(csv)
    assert len(fp) == 16 and int(fp, 16) >= 0
    assert reference_fingerprint(load_reference(sources / "ours.npz")) == fp
    flipped = csv.slice(0)
    flipped.q[:, 3:7] *= -1.0  # the same orientations
    assert reference_fingerprint(flipped) == fp
    assert reference_fingerprint(csv.slice(1)) != fp
    moved = csv.slice(0)
    moved.q[10, 7 + KNEE] += 1e-3
    assert reference_fingerprint(moved) != fp
    coarse = csv.slice(0)
    coarse.dt, coarse.time_s = 0.04, csv.time_s * 2
    assert reference_fingerprint(coarse) != fp


def _zero_profile(num: int, alpha: float) -> WrenchProfile:
    return WrenchProfile(
        alpha=alpha,
        wrench_w=np.zeros((num, 6)),
        contact_wrench_w=np.zeros((num, 2, 6)),
        corner_forces_w=np.zeros((num, 2, 4, 3)),
        tau_nm=np.zeros((num, 29)),
        missing_torque_nm=np.zeros((num, 29)),
        residual=np.zeros(num),
        solved=np.ones(num, dtype=bool),
        unaided=np.ones(num, dtype=bool),
        iterations=np.ones(num, dtype=np.int64),
        warm_started=np.ones(num, dtype=bool),
        solve_time_s=np.zeros(num),
        status=["solved"] * num,
    )


@pytest.fixture(scope="module")
def artifact_folder(g1_pin, rows, tmp_path_factory):
    """A 1.6 s two-phase artifact (zero wrench profiles: no solve needed)."""
    clip = reference_from_clip_rows(rows, FPS, name="tiny", robot=g1_pin)[0]
    num = clip.num_frames
    ref = Reference(
        time_s=clip.time_s,
        q=clip.q,
        v=clip.v,
        a=clip.a,
        contacts=clip.contacts,
        phase=(np.arange(num) >= num // 2).astype(np.int64),
        phase_names=("first", "second"),
        dt=clip.dt,
        name="tiny",
    ).validate()
    art = build_artifact("tiny", ref, {0.5: _zero_profile(num, 0.5)}, BoundRule(novice_alpha=0.5))
    return art.save(tmp_path_factory.mktemp("art") / "oracle", plots=False)


def test_artifact_reference_keeps_its_phases(artifact_folder):
    stored = OracleArtifact.load(artifact_folder).reference
    ref = load_reference(artifact_folder)
    assert ref.phase_names == ("first", "second")
    assert ref.name == "tiny"
    np.testing.assert_array_equal(ref.q, stored.q)
    np.testing.assert_array_equal(ref.phase, stored.phase)
    assert reference_fingerprint(ref) == reference_fingerprint(stored)
    part = load_reference(artifact_folder, frames=(20, 80), name="part")
    assert part.num_frames == 60 and part.name == "part"
    np.testing.assert_array_equal(part.q, stored.q[20:80])
    np.testing.assert_array_equal(part.phase, stored.phase[20:80])
    assert part.time_s[0] == 0.0


def _csv(tmp_path, name, rows):
    path = tmp_path / name
    np.savetxt(path, rows, delimiter=",")
    return path


def _npz(tmp_path, name, **arrays):
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def test_bad_inputs_give_one_line_naming_the_input(
    g1_pin, rows, sources, artifact_folder, tmp_path
):
    wbt = wbt_arrays(g1_pin, rows, FPS, "isaac")
    nan_rows = rows.copy()
    nan_rows[5, 10] = np.nan
    nan_wbt = dict(wbt, joint_pos=wbt["joint_pos"].copy())
    nan_wbt["joint_pos"][7, 3] = np.inf
    (tmp_path / "plain_dir").mkdir()
    (tmp_path / "clip.txt").write_text("1,2,3\n")
    cases = [
        (tmp_path / "missing.csv", None, "does not exist"),
        (tmp_path / "plain_dir", None, "not an oracle artifact"),
        (tmp_path / "clip.txt", None, "unknown format"),
        (_csv(tmp_path, "cols.csv", rows[:, :35]), None, "expected 36 columns"),
        (_csv(tmp_path, "nan.csv", nan_rows), None, "NaN/inf at frame 5, column 10"),
        (_csv(tmp_path, "deg.csv", np.c_[rows[:, :7], np.degrees(rows[:, 7:])]), None, "degrees"),
        (_csv(tmp_path, "short.csv", rows[:20]), None, "shorter than 1 s"),
        (sources / "clip.csv", (0, 20), "shorter than 1 s"),
        (sources / "clip.csv", (0, 600), "out of range: the source has 60 frames"),
        (sources / "clip.csv", (30, 30), "empty"),
        (sources / "wbt.npz", (10, 61), "out of range"),
        (artifact_folder, (0, 20), "shorter than 1 s"),
        (artifact_folder, (0, 100), "out of range"),
        (_npz(tmp_path, "nan_wbt.npz", **nan_wbt), None, "'joint_pos' has NaN/inf"),
        (
            _npz(tmp_path, "deg_wbt.npz", **dict(wbt, joint_pos=np.degrees(wbt["joint_pos"]))),
            None,
            "degrees",
        ),
        (
            _npz(tmp_path, "nofps.npz", **{k: v for k, v in wbt.items() if k != "fps"}),
            None,
            "lacks ['fps']",
        ),
        (
            _npz(tmp_path, "quat3.npz", **dict(wbt, body_quat_w=wbt["body_quat_w"][..., :3])),
            None,
            "'body_quat_w' has shape",
        ),
        (
            _npz(tmp_path, "len.npz", **dict(wbt, joint_pos=wbt["joint_pos"][:50])),
            None,
            "same frames",
        ),
        (
            _npz(tmp_path, "cols.npz", **dict(wbt, joint_pos=wbt["joint_pos"][:, :23])),
            None,
            "23 columns",
        ),
        (
            _npz(
                tmp_path,
                "xyzw.npz",
                **dict(wbt, body_quat_w=wbt["body_quat_w"][..., [1, 2, 3, 0]]),
            ),
            None,
            "no joint order reproduces",
        ),
        (
            _npz(
                tmp_path,
                "pelvis_only.npz",
                **dict(
                    wbt, body_pos_w=wbt["body_pos_w"][:, :1], body_quat_w=wbt["body_quat_w"][:, :1]
                ),
            ),
            None,
            "joint_order='isaaclab'",
        ),
        (_npz(tmp_path, "other.npz", poses=rows), None, "expected 'qpos'"),
    ]
    for path, frames, what in cases:
        with pytest.raises(ClipError) as err:
            load_reference(path, frames=frames)
        message = str(err.value)
        assert what in message, (path.name, message)
        assert path.name in message, message
        assert "\n" not in message, message
    with pytest.raises(ClipError, match="joint_order 'isaac' is unknown"):
        load_reference(sources / "wbt.npz", joint_order="isaac")


def test_artifact_folder_damaged_is_one_line(artifact_folder, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(artifact_folder, broken)
    summary = json.loads((broken / "oracle.json").read_text())
    summary["task"] = "edited"
    (broken / "oracle.json").write_text(json.dumps(summary))
    with pytest.raises(ClipError) as err:
        load_reference(broken)
    assert "broken" in str(err.value) and "\n" not in str(err.value)


def test_velocities_are_recomputed_not_read(g1_pin, rows, sources):
    ref = load_reference(sources / "wbt.npz")  # the file's velocities are zeros
    inner = slice(5, -5)
    assert np.abs(ref.v[inner, 6 + SHOULDER]).max() > 0.5
    assert ref.v.shape == (ref.num_frames, NV)
