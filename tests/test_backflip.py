"""The backflip TO: a tiny hop solved and audited, the audit rejecting corrupted solutions, a clear
message for infeasible settings, sampling and frame conversions; the full flip is a slow test."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optimal_control.backflip.audit import audit_solution
from optimal_control.backflip.config import AIR_PHASE, BackflipConfig, tiny_hop_config
from optimal_control.backflip.sagittal import NR, build_sagittal_model
from optimal_control.backflip.solve import InfeasibleBackflipError, solve_backflip_to
from optimal_control.backflip.trajectory import sample_solution, wrench_body_to_world_com
from optimal_control.backflip.transcription import make_grid

# a small vertical hop (no turn) on a coarse grid: the same NLP, solved in seconds
TINY_HOP = dataclasses.replace(tiny_hop_config(), max_iter=200, cache_dir="")


@pytest.fixture(scope="module")
def model():
    return build_sagittal_model()


@pytest.fixture(scope="module")
def hop(model):
    return solve_backflip_to(TINY_HOP, model)


def test_sagittal_inverse_dynamics_matches_pinocchio(model):
    """The TO's inverse dynamics (r -> full q, v, a; contact forces) equals pinocchio's RNEA."""
    import pinocchio as pin

    from optimal_control.backflip.audit import _contact_fext

    rng = np.random.default_rng(0)
    r = model.r_stand() + 0.2 * rng.normal(size=model.lower_r.shape)
    rd, rdd, force = rng.normal(size=NR), rng.normal(size=NR), 100 * rng.normal(size=4)
    tau = np.asarray(model.inverse_dynamics(r, rd, rdd, force)).ravel()
    q, v, a = (np.asarray(x).ravel() for x in model.full_state(r, rd, rdd))
    pmodel = model.robot.model
    data = pmodel.createData()
    pin.forwardKinematics(pmodel, data, q, v)
    pin.updateFramePlacements(pmodel, data)
    expected = pin.rnea(pmodel, data, q, v, a, _contact_fext(model, data, q, force))
    assert np.abs(tau - expected).max() < 1e-9
    # the sagittal velocity map is the derivative of the configuration map
    eps = 1e-7
    q2 = np.asarray(model.full_state(r + eps * rd, rd, rdd)[0]).ravel()
    assert np.abs(pin.difference(pmodel, q, q2) / eps - v).max() < 1e-5


def test_tiny_hop_solves_and_passes_the_audit(hop, model):
    assert hop.success, hop.violations
    report = audit_solution(hop.solution, TINY_HOP, model)
    assert report.passed, report.failures()
    checks = report.checks
    assert checks["dynamics residual (base rows vs pelvis wrench)"].value < 1e-3
    assert abs(report.energy_total["contact_work"]) < 1e-3
    # the hop really leaves the ground and lands at rest
    assert report.extra["flight_time_s"] >= TINY_HOP.air_duration_s[0] - 1e-6
    assert np.abs(hop.solution.rd[-1]).max() < 1e-6


def test_audit_rejects_corrupted_solutions(hop, model):
    grid = make_grid(TINY_HOP)
    # ground forces scaled up: dynamics no longer hold
    bad = dataclasses.replace(hop.solution, force_n=hop.solution.force_n * 1.3)
    report = audit_solution(bad, TINY_HOP, model, grid=grid)
    assert not report.passed
    assert any("dynamics residual" in f for f in report.failures())
    # a loaded sole dragged along the floor: the ground would do work
    r = hop.solution.r.copy()
    rd = hop.solution.rd.copy()
    k = grid.takeoff_knot - 2
    rd[k, 0] += 0.5
    bad = dataclasses.replace(hop.solution, rd=rd, r=r)
    failures = audit_solution(bad, TINY_HOP, model, grid=grid).failures()
    assert any("loaded sole speed" in f for f in failures)
    assert any("integration residual" in f for f in failures)


def test_infeasible_setting_names_violated_groups(model, tmp_path):
    weak = dataclasses.replace(TINY_HOP, torque_scale=0.02, forbid_wrench=True, max_iter=40)
    path = tmp_path / "last.npz"
    with pytest.raises(InfeasibleBackflipError) as err:
        solve_backflip_to(weak, model, failure_path=path)
    message = str(err.value)
    assert "Violated constraint groups" in message
    assert "torque limits" in message or "inverse dynamics" in message
    assert path.is_file()
    assert np.load(path)["r"].shape == (make_grid(weak).num_knots, NR)


def test_bad_config_values_are_named():
    with pytest.raises(ValueError, match="crouch"):
        BackflipConfig(crouch_duration_s=(0.5, 0.2, 0.3)).validate()
    with pytest.raises(ValueError, match="torque_scale"):
        BackflipConfig(torque_scale=-1.0).validate()


def test_sampling_reproduces_knots_and_zero_air_forces(hop, model):
    grid = make_grid(TINY_HOP)
    sol = hop.solution
    times = sol.knot_times_s(grid)
    rate = 400.0
    flip = sample_solution(sol, grid, model, rate)
    for k in (0, grid.takeoff_knot, grid.num_knots - 2):
        i = int(round(times[k] * rate))
        if abs(i / rate - times[k]) < 1e-9:
            assert np.allclose(flip.r[i], sol.r[k], atol=1e-9)
    assert np.all(flip.force_n[flip.phase == AIR_PHASE] == 0.0)
    ref = flip.to_reference()
    assert ref.contacts[flip.phase == AIR_PHASE].sum() == 0


def test_wrench_conversion_moves_torque_to_the_com():
    q = np.zeros((1, 36))
    q[0, 6] = 1.0  # identity orientation
    lever = np.array([0.0, 0.0, 0.1])
    wrench_b = np.array([[10.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    out = wrench_body_to_world_com(q, wrench_b, lever)
    # a force through the pelvis origin has a moment -lever x f about the CoM
    assert np.allclose(out[0, :3], [10.0, 0.0, 0.0])
    assert np.allclose(out[0, 3:], -np.cross(lever, [10.0, 0.0, 0.0]))


@pytest.mark.slow
def test_full_backflip_solves_audits_and_needs_little_help(model):
    cfg = dataclasses.replace(BackflipConfig(), cache_dir="")
    result = solve_backflip_to(cfg, model)
    assert result.success
    report = audit_solution(result.solution, cfg, model)
    assert report.passed, report.failures()
    assert abs(result.solution.r[-1, 2] + 2 * np.pi) < 1e-6
    assert report.extra["flight_time_s"] > 0.3


def test_eta0_comparison_with_the_paper_table():
    from optimal_control.backflip.config import PHASE_NAMES
    from optimal_control.backflip.novice import compare_with_paper, comparison_markdown
    from optimal_control.bounds import PAPER_ETA0

    paper = np.asarray(PAPER_ETA0["backflip"]["all"])
    same = compare_with_paper(paper, PHASE_NAMES)
    assert all(v["same_pattern"] for v in same["axes"].values())
    assert same["axes"]["fz"]["paper_raised"] == ["jump", "air"]
    flat = compare_with_paper(np.ones((5, 6)), PHASE_NAMES)
    assert not flat["axes"]["fz"]["same_pattern"] and flat["axes"]["fx"]["same_pattern"]
    assert "| fz | jump, air | none (flat) | no |" in comparison_markdown(flat)


def test_mapped_mx_transcription_solves_the_hop(model):
    cfg = dataclasses.replace(TINY_HOP, symbolic="MX")
    result = solve_backflip_to(cfg, model)
    assert result.success
    assert audit_solution(result.solution, cfg, model).passed


def test_playback_runs_the_hop_in_mujoco(hop, model):
    from optimal_control.backflip.playback import PlaybackConfig, play_back

    grid = make_grid(TINY_HOP)
    with pytest.raises(ValueError, match="MuJoCo step"):
        play_back(sample_solution(hop.solution, grid, model, 50.0), True)
    flip = sample_solution(hop.solution, grid, model, 200.0)
    result, qpos = play_back(
        flip, False, PlaybackConfig(settle_s=0.2), turn_rad=0.0, gain_scale=3.0
    )
    assert qpos.shape == (len(flip.time_s) + 40, 36)
    assert np.all(np.isfinite(qpos))
    assert result.gain_scale == 3.0 and not result.with_wrench

    # the push-off works in MuJoCo too: from the bottom of the crouch the pelvis rises by at least
    # half as much as in the reference
    def rise(z):
        low = int(np.argmin(z[: len(flip.time_s)]))
        return z[low:].max() - z[low]

    assert rise(qpos[:, 2]) > 0.5 * rise(flip.q[:, 2]) > 0.0


def test_flight_alone_follows_the_reference_and_diagnostics_are_reported(hop, model):
    """The Air phase played from the reference take-off state (contacts off) stays on the
    reference: flight modelling (inertias, armature, torque timing, wrench convention) agrees."""
    from optimal_control.backflip.playback import (
        PlaybackConfig,
        air_inverse_dynamics_gap_nm,
        play_back,
        play_flight,
    )

    flip = sample_solution(hop.solution, make_grid(TINY_HOP), model, 200.0)
    flight = play_flight(flip, True, PlaybackConfig(), gain_scale=3.0)
    assert abs(flight.pitch_error_at_touchdown_rad) < 0.05
    assert abs(flight.height_error_at_touchdown_m) < 0.02
    assert flight.max_joint_error_rad < 0.1
    result, _ = play_back(flip, True, PlaybackConfig(settle_s=0.0), turn_rad=0.0, gain_scale=3.0)
    assert np.isfinite(result.takeoff_ang_momentum_y_nms)
    assert np.isfinite(result.ref_takeoff_ang_momentum_y_nms)
    # the hop takes off upwards in both
    assert result.ref_takeoff_com_velocity_xz_mps[1] > 0.0
    assert result.takeoff_com_velocity_xz_mps[1] > 0.0
    assert set(result.to_dict()) >= {"takeoff_ang_momentum_y_nms", "completed_flip"}
    # MuJoCo's inverse dynamics of the sampled flight equals the TO torques (same model, frames,
    # armature and wrench convention)
    gap = air_inverse_dynamics_gap_nm(flip)
    assert len(gap) > 10 and np.median(gap) < 1e-6
    with pytest.raises(ValueError, match="contact_timeconst_s"):
        play_back(flip, True, PlaybackConfig(contact_timeconst_s=0.001), turn_rad=0.0)
