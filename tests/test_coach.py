"""The coach: gains from the robot, batched numpy/torch evaluation, tolerance band, bound, and
in MuJoCo a pushed standing robot that the coach keeps up and that falls without it."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from optimal_control.artifact import build_artifact
from optimal_control.bounds import BoundRule
from optimal_control.coach import (
    CoachConfig,
    Randomisation,
    ValidationConfig,
    coach_from_artifact,
    coach_gains,
    run_episode,
)
from optimal_control.reference import static_reference
from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig
from robots.conventions import quat_xyzw_to_wxyz


@pytest.fixture(scope="module")
def stand_artifact(g1_pin):
    """A 3 s standing reference with its oracle profiles (alpha 1 and 0.5)."""
    ref = static_reference(g1_pin.q_stand, 150, 0.02)
    profiles = {a: WrenchQP(WrenchQPConfig(alpha=a)).solve_reference(ref) for a in (1.0, 0.5)}
    return build_artifact("stand", ref, profiles, BoundRule())


def _state(g1_pin, n=1):
    q = g1_pin.q_stand
    pos = np.tile(q[:3], (n, 1))
    quat = np.tile(quat_xyzw_to_wxyz(q[3:7]), (n, 1))
    return pos, quat, np.zeros((n, 3)), np.zeros((n, 3))


def test_gains_come_from_mass_and_inertia(g1_pin):
    cfg = CoachConfig(natural_frequency_hz=1.0, damping_ratio=1.0)
    gains = coach_gains(g1_pin, cfg)
    omega = 2 * np.pi
    np.testing.assert_allclose(np.diag(gains["kp_force"]), g1_pin.total_mass_kg * omega**2)
    np.testing.assert_allclose(np.diag(gains["kd_force"]), 2 * g1_pin.total_mass_kg * omega)
    inertia = gains["inertia_kg_m2"]
    assert np.all(np.linalg.eigvalsh(inertia) > 0.1)  # a whole robot, not the pelvis alone
    np.testing.assert_allclose(gains["kp_torque"], inertia * omega**2)


def test_coach_restores_pose_numpy_equals_torch_and_respects_band_and_bound(g1_pin, stand_artifact):
    coach = coach_from_artifact(stand_artifact, CoachConfig(bounded=False))
    pos, quat, lin, ang = _state(g1_pin, 3)
    pos[1, 0] += 0.02  # 2 cm ahead of the reference
    yaw = 0.1
    quat[2] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]  # yawed by +0.1 rad
    t = np.array([0.5, 0.5, 0.5])
    w = coach.wrench(pos, quat, lin, ang, t)
    assert w.shape == (3, 6)
    np.testing.assert_allclose(w[0], stand_artifact.profiles[1.0].wrench_w[25], atol=1e-9)
    kp = coach.gains["kp_force"][0, 0]
    assert w[1, 0] == pytest.approx(-0.02 * kp, rel=1e-3)  # pushed back
    assert w[2, 5] < -0.05 * coach.gains["kp_torque"][2, 2]  # yawed back
    as_torch = [torch.as_tensor(x, dtype=torch.float32) for x in (pos, quat, lin, ang, t)]
    w_torch = coach.wrench(*as_torch)
    assert isinstance(w_torch, torch.Tensor) and w_torch.dtype == torch.float32
    np.testing.assert_allclose(w_torch.numpy(), w, rtol=1e-4, atol=1e-3)
    # Tolerance band: nothing inside it, help beyond it.
    band = coach_from_artifact(
        stand_artifact,
        CoachConfig(bounded=False, band_position_m=0.05, band_orientation_rad=0.15),
    )
    assert np.abs(band.wrench(pos, quat, lin, ang, t)).max() == 0.0
    pos[1, 0] += 0.1
    assert band.wrench(pos, quat, lin, ang, t)[1, 0] < -50.0  # K_p (0.12 - 0.05) m
    # Bound: clipped to eta0 of the phase.
    bounded = coach_from_artifact(stand_artifact, CoachConfig())
    assert np.all(np.abs(bounded.wrench(pos, quat, lin, ang, t)) <= stand_artifact.eta0[0] + 1e-9)


def test_coach_keeps_a_pushed_robot_standing_in_mujoco(stand_artifact, g1_mj):
    cfg = ValidationConfig()
    push = Randomisation(friction=(1.0, 1.0), payload_kg=(2.0, 2.0), push_force_n=(160.0, 160.0))
    rng = np.random.default_rng(0)
    alone = run_episode(None, stand_artifact, g1_mj, cfg, rng, push)
    coach = coach_from_artifact(stand_artifact, CoachConfig(bounded=False))
    rng = np.random.default_rng(0)
    helped = run_episode(coach, stand_artifact, g1_mj, cfg, rng, push)
    assert not alone.completed
    assert helped.completed, helped.reason
    assert np.abs(helped.wrench_w[:, :2]).max() > 20.0  # the coach pushed back


def test_cli_coach_writes_json_and_plot(stand_artifact, tmp_path):
    from a2cf_mb.cli import main

    folder = stand_artifact.save(tmp_path / "stand", plots=False)
    assert main(["coach", str(folder), "--validation-episodes", "1"]) == 0
    out = tmp_path / "stand-coach"
    report = json.loads((out / "coach.json").read_text())
    assert (out / "coach.png").is_file()
    assert set(report["variants"]) == {"no_help", "coach_eta0", "coach", "coach_band"}
    assert report["variants"]["coach"]["nominal_completed"]
