"""Walk (placo) and dance references, and the oracle pipeline end to end on small inputs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from a2cf_mb.cli import main
from optimal_control.artifact import OracleArtifact
from optimal_control.dance import SWING_WINDOWS_S, DanceConfig, built_in_dance, pose_summary
from optimal_control.oracle import OracleConfig, solve_reference_oracle
from optimal_control.walk import WALK_PHASES, WalkConfig, plan_walk, stance_slip_m
from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig
from robots import g1


@pytest.fixture(scope="module")
def walk_plan():
    """A short forward walk."""
    return plan_walk(WalkConfig(vx=0.4, duration=5.0))


@pytest.fixture(scope="module")
def dance_plan():
    """The built-in dance."""
    return built_in_dance(DanceConfig())


def _within_limits(robot, ref, tol=1e-6):
    joints = ref.q[:, robot.joint_q_index]
    return np.all(joints >= robot.position_lower_rad - tol) and np.all(
        joints <= robot.position_upper_rad + tol
    )


def test_walk_reference_follows_the_command(walk_plan, g1_pin):
    ref = walk_plan.reference
    assert ref.phase_names == WALK_PHASES
    assert ref.dt == pytest.approx(0.02)
    # Phases are the contact schedule: single support has exactly one sole down.
    np.testing.assert_array_equal(ref.phase == 1, ref.contacts.sum(axis=1) == 1)
    assert (ref.phase == 1).any() and (ref.phase == 0).any()
    assert not (ref.contacts.sum(axis=1) == 0).any()
    assert walk_plan.max_stance_slip_m < 1e-3  # stance soles stay put
    assert _within_limits(g1_pin, ref)
    # Footsteps alternate and advance; the robot moves forward at about the command.
    sides = walk_plan.footstep_sides
    assert all(a != b for a, b in zip(sides[:-1], sides[1:], strict=True)) or len(sides) < 3
    # Same-foot stride = 2 steps of vx * step period; the base keeps about that pace mid-walk.
    cfg = WalkConfig(vx=0.4, duration=5.0)
    period = cfg.single_support_s * (1 + cfg.double_support_ratio)
    strides = np.diff(walk_plan.footsteps_w[2:-2:2, 0])
    np.testing.assert_allclose(strides, 2 * cfg.vx * period, atol=1e-6)
    middle = slice(ref.num_frames // 3, 2 * ref.num_frames // 3)
    mean_vx = (ref.q[middle, 0][-1] - ref.q[middle, 0][0]) / (
        ref.time_s[middle][-1] - ref.time_s[middle][0]
    )
    assert abs(mean_vx - cfg.vx) < 0.1
    assert abs(ref.q[-1, 1]) < 0.05  # no lateral drift
    data = g1_pin.data()
    com_z = np.array([pin.centerOfMass(g1_pin.model, data, q)[2] for q in ref.q])
    assert np.all(np.abs(com_z - WalkConfig().com_height_m) < 0.03)
    # The whole-body CoM follows placo's planned CoM.
    com = np.array([pin.centerOfMass(g1_pin.model, data, q) for q in ref.q])
    assert np.abs(com - ref.extras["com_plan_w"]).max() < 0.02


def test_walk_turns_with_a_yaw_command(g1_pin):
    ref = plan_walk(WalkConfig(vx=0.2, wz=0.3, duration=5.0)).reference
    yaw = [pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).matrix())[2] for q in ref.q[[0, -1]]]
    assert yaw[1] - yaw[0] > 0.5  # about wz x the walking time


def test_walk_wrench_profile(walk_plan):
    ref = walk_plan.reference
    prof = WrenchQP(WrenchQPConfig(alpha=1.0)).solve_reference(ref)
    assert prof.solved.all()
    assert prof.residual.max() < 1e-4
    # Standing still at the start needs no help; walking needs some, within reason.
    assert prof.unaided[:10].all()
    assert prof.wrench_norm.max() < 100.0


def test_dance_reference(dance_plan, g1_pin):
    ref = dance_plan.reference
    assert 10.0 <= ref.duration_s <= 20.0
    feet = {"left": 0, "right": 1}
    swinging = np.zeros_like(ref.contacts)
    for foot, start, stop in SWING_WINDOWS_S:
        inside = (ref.time_s >= start + 0.05) & (ref.time_s < stop - 0.05)
        assert inside.any() and not ref.contacts[inside, feet[foot]].any()
        swinging[(ref.time_s > start) & (ref.time_s < stop), feet[foot]] = True
    assert ref.contacts[~swinging].all()  # every other frame: both soles on the floor
    assert stance_slip_m(ref) < 2e-3
    assert dance_plan.max_foot_error_m < 5e-3
    assert _within_limits(g1_pin, ref)
    summary = pose_summary(ref)
    assert summary["com_z_range_m"][1] - summary["com_z_range_m"][0] > 0.15  # the squat
    assert summary["waist_yaw_range_rad"][0] < -0.5 < 0.5 < summary["waist_yaw_range_rad"][1]
    assert summary["mean_abs_from_stand_rad"] >= 0.25  # it moves like a dance, not a statue
    parts = summary["mean_abs_from_stand_rad_by_part"]
    assert parts["legs"] > 0.15 and parts["arms"] > 0.15
    quat_last = ref.q[-1, 3:7]  # x y z w: the turn ends facing about 90 degrees to the left
    yaw = 2.0 * np.arctan2(quat_last[2], quat_last[3])
    assert abs(yaw - np.pi / 2) < 0.1
    assert np.abs(ref.v[-10:]).max() < 0.05  # and still


def test_oracle_pipeline_on_a_walk_slice(walk_plan, tmp_path):
    ref = walk_plan.reference.slice(30, 90)
    cfg = OracleConfig(alphas=(1.0, 0.5), video=False, progress=False, out=str(tmp_path / "w"))
    art, folder = solve_reference_oracle("walk", ref, cfg, {"note": "slice"})
    loaded = OracleArtifact.load(folder)
    assert loaded.eta0.shape == (2, 6)
    assert art.novice_profile.solved.all() and loaded.novice_profile.solved.all()
    assert loaded.phase_names == WALK_PHASES
    assert "no video" in loaded.video_note
    summary = OracleArtifact.read_summary(folder).raw
    assert summary["paper_eta0"] == [[40.0, 40.0, 10.0, 40.0, 40.0, 40.0]]
    assert summary["extra"]["note"] == "slice"
    # The upper envelope (no ground) carries the weight: far above the novice bound.
    weight = 33.0 * 9.81
    assert np.all(loaded.extra_arrays["no_contact_wrench_w"][:, 2] > 0.8 * weight)
    # Monotone in alpha frame by frame.
    n1 = np.linalg.norm(art.profiles[1.0].wrench_w, axis=1)
    n05 = np.linalg.norm(art.profiles[0.5].wrench_w, axis=1)
    assert np.all(n05 >= n1 - 1e-2)


def test_cli_solve_dance_with_a_clip(tmp_path, g1_pin):
    rows = np.tile(g1_pin.q_stand, (40, 1))
    rows[:, 7 + g1.JOINT_NAMES.index("right_elbow_joint")] += 0.3 * np.sin(np.arange(40) / 5)
    clip = tmp_path / "clip.csv"
    np.savetxt(clip, rows, delimiter=",")
    out = tmp_path / "dance"
    code = main(
        ["solve-dance", "--clip", str(clip), "--no-video", "--no-progress", "--out", str(out)]
    )
    assert code == 0
    art = OracleArtifact.load(out)
    assert art.task == "dance" and art.phase_names == ("dance",)
    assert art.reference.num_frames == 66  # 39 / 30 = 1.3 s at 50 Hz, both ends included
    assert art.novice_profile.unaided.all()  # a slow arm motion on both feet needs no help
    bad = tmp_path / "bad.csv"
    np.savetxt(bad, rows[:, :20], delimiter=",")
    assert main(["solve-dance", "--clip", str(bad), "--no-video", "--out", str(out)]) == 2


def test_render_two_tiny_frames(walk_plan, tmp_path):
    from optimal_control.render import RenderConfig, render_reference

    path = render_reference(
        walk_plan.reference,
        tmp_path / "r.mp4",
        RenderConfig(width=96, height=64, max_frames=2),
        wrench_w=np.ones((walk_plan.reference.num_frames, 6)),
    )
    assert path.stat().st_size > 0
    assert [p.name for p in tmp_path.iterdir()] == ["r.mp4"]  # no temporary file left


def test_a_ghost_render_draws_a_second_bluish_g1(walk_plan, tmp_path):
    """The reference overlaid on itself as a ghost: same camera, so frames differ only where the
    robot is, tinted towards the ghost's blue; beside it (or a wrong shape) also works / fails."""
    import imageio.v2 as imageio

    from optimal_control.render import RenderConfig, RenderUnavailableError, render_reference

    ref = walk_plan.reference
    cfg = RenderConfig(width=96, height=64, max_frames=3, overlay_text=False)
    try:
        plain = render_reference(ref, tmp_path / "plain.mp4", cfg)
    except RenderUnavailableError as err:
        pytest.skip(f"no offscreen rendering here: {err}")
    ghost = render_reference(ref, tmp_path / "ghost.mp4", cfg, ghost_q=ref.q)
    a, b = (np.stack(imageio.mimread(p)).astype(float) for p in (plain, ghost))
    assert a.shape == b.shape == (3, 64, 96, 3)
    changed = np.abs(b - a).sum(axis=-1) > 30  # beyond the codec's noise
    assert 0.005 < changed.mean() < 0.5  # the robot's pixels, not the whole frame
    tint = (b - a)[changed]
    assert tint[:, 2].mean() > 0 > tint[:, 0].mean()  # bluer, less red: the ghost's colour
    beside = dataclasses.replace(cfg, ghost_side_m=1.0, overlay_text=True)
    side = render_reference(ref, tmp_path / "side.mp4", beside, ghost_q=ref.q)
    assert len(imageio.mimread(side)) == 3
    # a caption per frame (a walk's command) is drawn under the time: the text's pixels change
    big = dataclasses.replace(beside, width=192, height=128)
    lines = [f"command: vx {0.01 * k:+.2f} m/s" for k in range(ref.num_frames)]
    plain_big = render_reference(ref, tmp_path / "big.mp4", big, ghost_q=ref.q)
    captioned = render_reference(ref, tmp_path / "cap.mp4", big, ghost_q=ref.q, captions=lines)
    c, d = (np.stack(imageio.mimread(p)).astype(float) for p in (plain_big, captioned))
    text = np.abs(d - c).sum(axis=-1) > 60
    assert all(text[k].mean() > 0.005 for k in range(3)), text.mean(axis=(1, 2))
    with pytest.raises(ValueError, match="one line per frame"):
        render_reference(ref, tmp_path / "bad.mp4", cfg, captions=lines[:3])
    with pytest.raises(ValueError, match="one configuration per frame"):
        render_reference(ref, tmp_path / "bad.mp4", cfg, ghost_q=ref.q[:5])


def test_a_render_killed_mid_video_leaves_the_old_file_and_no_partial(
    walk_plan, tmp_path, monkeypatch
):
    """The mp4 is written beside the target and renamed at the end (eval --video, the demo)."""
    import imageio.v2 as imageio

    from optimal_control.render import RenderConfig, render_reference

    real = imageio.get_writer

    class Dying:
        def __init__(self, *args, **kwargs):
            self.writer = real(*args, **kwargs)
            self.frames = 0

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.writer.close()

        def append_data(self, frame):
            self.frames += 1
            if self.frames == 2:
                raise KeyboardInterrupt  # a kill between two frames
            self.writer.append_data(frame)

    target = tmp_path / "r.mp4"
    target.write_bytes(b"the previous video")
    monkeypatch.setattr(imageio, "get_writer", Dying)
    with pytest.raises(KeyboardInterrupt):
        render_reference(
            walk_plan.reference, target, RenderConfig(width=96, height=64, max_frames=3)
        )
    assert target.read_bytes() == b"the previous video"
    assert [p.name for p in tmp_path.iterdir()] == ["r.mp4"]


@pytest.mark.slow
def test_full_walk_and_dance_artifacts_with_video(tmp_path):
    """The two CLI solves at their defaults, video included (minutes on a laptop CPU)."""
    assert main(["solve-walk", "--no-progress", "--out", str(tmp_path / "walk")]) == 0
    walk = OracleArtifact.load(tmp_path / "walk")
    assert walk.video == "reference.mp4" and (tmp_path / "walk" / "reference.mp4").is_file()
    # Walking needs more help in single support than in double support.
    assert walk.eta0[1].sum() > walk.eta0[0].sum()
    assert main(["solve-dance", "--no-progress", "--out", str(tmp_path / "dance")]) == 0
    dance = OracleArtifact.load(tmp_path / "dance")
    assert dance.reference.duration_s >= 10.0
    assert all(p.solved.mean() > 0.95 for p in dance.profiles.values())
