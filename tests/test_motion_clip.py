"""Motion clips: loading (CSV / NPZ), validation errors, resampling, differentiation, contacts."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optimal_control.motion_clip import (
    ClipConfig,
    ClipError,
    differentiate,
    infer_contacts,
    load_motion_clip,
)
from robots import g1

FPS = 30.0
KNEE = g1.JOINT_NAMES.index("left_knee_joint")
SHOULDER = g1.JOINT_NAMES.index("right_shoulder_pitch_joint")
YAW_RATE = 0.4  # [rad/s]
SPEED = 0.3  # [m/s] forward, in the world
WAVE = 2.0  # [rad/s]


def analytic_clip(robot, times: np.ndarray) -> np.ndarray:
    """Rows (T, 36): walking-free motion with a yawing, translating base and waving joints."""
    rows = np.tile(robot.q_stand, (times.shape[0], 1))
    rows[:, 0] += SPEED * times
    yaw = YAW_RATE * times
    rows[:, 3:7] = np.stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)
    rows[:, 7 + SHOULDER] = 0.2 + 0.5 * np.sin(WAVE * times)
    rows[:, 7 + KNEE] = 0.669 + 0.1 * np.sin(WAVE * times)
    return rows


def write_csv(path, rows):
    np.savetxt(path, rows, delimiter=",")
    return path


def test_csv_clip_is_resampled_and_differentiated(tmp_path, g1_pin):
    times = np.arange(60) / FPS  # 2 s
    path = write_csv(tmp_path / "clip.csv", analytic_clip(g1_pin, times))
    ref = load_motion_clip(path, ClipConfig(ground_to_lowest_sole=False))
    assert ref.dt == pytest.approx(0.02)
    assert ref.num_frames == int(np.floor(times[-1] * 50 + 1e-9)) + 1
    expected = analytic_clip(g1_pin, ref.time_s)
    np.testing.assert_allclose(ref.q[:, 7:], expected[:, 7:], atol=2e-3)
    np.testing.assert_allclose(ref.q[:, :3], expected[:, :3], atol=1e-6)
    # Slerp: the yaw is exact at every resampled frame (up to the quaternion sign).
    dots = np.abs(np.sum(ref.q[:, 3:7] * expected[:, 3:7], axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-9)
    inner = slice(5, -5)  # away from the filter's edges
    qdot = 0.5 * WAVE * np.cos(WAVE * ref.time_s)
    np.testing.assert_allclose(ref.v[inner, 6 + SHOULDER], qdot[inner], atol=0.02)
    np.testing.assert_allclose(
        ref.a[inner, 6 + SHOULDER], -WAVE * WAVE * 0.5 * np.sin(WAVE * ref.time_s)[inner], atol=0.1
    )
    np.testing.assert_allclose(ref.v[inner, 5], YAW_RATE, atol=1e-3)  # omega_z in the pelvis frame
    # Base linear velocity is in the pelvis frame: world (SPEED, 0, 0) rotated by -yaw.
    yaw = YAW_RATE * ref.time_s[inner]
    np.testing.assert_allclose(ref.v[inner, 0], SPEED * np.cos(yaw), atol=2e-3)
    np.testing.assert_allclose(ref.v[inner, 1], -SPEED * np.sin(yaw), atol=2e-3)
    assert ref.contacts.all()  # both soles stay on the floor


def test_npz_forms_match_csv(tmp_path, g1_pin):
    rows = analytic_clip(g1_pin, np.arange(40) / FPS)
    from_csv = load_motion_clip(write_csv(tmp_path / "c.csv", rows))
    np.savez(tmp_path / "a.npz", qpos=rows, fps=FPS)
    np.savez(
        tmp_path / "b.npz",
        root_pos=rows[:, :3],
        root_quat_xyzw=rows[:, 3:7],
        joint_pos=rows[:, 7:],
    )
    for name in ("a.npz", "b.npz"):
        ref = load_motion_clip(tmp_path / name)
        np.testing.assert_allclose(ref.q, from_csv.q, atol=1e-12)
        np.testing.assert_allclose(ref.a, from_csv.a, atol=1e-9)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r[:, :30], "expected 36 columns"),
        (
            lambda r: np.where(np.arange(r.size).reshape(r.shape) == 100, np.nan, r),
            "NaN/inf at frame 2",
        ),
        (lambda r: r[:5], "at least 10 are needed"),
        (lambda r: np.concatenate([r[:, :3], 2 * r[:, 3:7], r[:, 7:]], axis=1), "norm 2.0000"),
        (lambda r: _set(r, 7 + KNEE, 5.0), "joint 'left_knee_joint' = 5.000"),
        (lambda r: _set(r, 7 + KNEE, 90.0), "look like degrees; convert them to radians"),
    ],
)
def test_bad_clips_are_rejected_with_a_clear_error(tmp_path, g1_pin, edit, message):
    rows = edit(analytic_clip(g1_pin, np.arange(30) / FPS))
    with pytest.raises(ClipError, match=message):
        load_motion_clip(write_csv(tmp_path / "bad.csv", rows))


def _set(rows, col, value):
    rows = rows.copy()
    rows[3, col] = value
    return rows


def test_unreadable_inputs(tmp_path):
    with pytest.raises(ClipError, match="does not exist"):
        load_motion_clip(tmp_path / "missing.csv")
    header = tmp_path / "header.csv"
    header.write_text("x,y,z\n1,2,3\n")
    with pytest.raises(ClipError, match="numeric CSV"):
        load_motion_clip(header)
    np.savez(tmp_path / "odd.npz", stuff=np.zeros(3))
    with pytest.raises(ClipError, match="expected 'qpos'"):
        load_motion_clip(tmp_path / "odd.npz")
    (tmp_path / "clip.bvh").write_text("")
    with pytest.raises(ClipError, match="unknown format"):
        load_motion_clip(tmp_path / "clip.bvh")


def test_contacts_from_height_and_speed(g1_pin):
    dt = 0.02
    q = np.tile(g1_pin.q_stand, (50, 1))
    q[20:30, 2] += 0.1  # a hop: both soles 10 cm up
    contacts = infer_contacts(q, dt, support_fallback=False)  # a hover, not a ballistic hop
    assert contacts[:19].all() and contacts[31:].all()
    assert not contacts[21:29].any()
    # A sole sliding fast along the floor is not in contact.
    slide = np.tile(g1_pin.q_stand, (20, 1))
    slide[:, 0] = np.arange(20) * dt * 1.0  # 1 m/s
    assert not infer_contacts(slide, dt).any()


def test_differentiate_integrates_back(g1_pin):
    dt = 0.02
    q = analytic_clip(g1_pin, np.arange(80) * dt)
    v, _ = differentiate(q, dt)
    # Integrating v over one step lands on the next configuration (second order).
    for t in range(5, 75):
        q_next = pin.integrate(g1_pin.model, q[t], v[t] * dt)
        assert np.abs(pin.difference(g1_pin.model, q_next, q[t + 1])).max() < 2e-3
