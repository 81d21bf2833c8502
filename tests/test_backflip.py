"""The backflip TO: a tiny hop solved and audited, the audit rejecting corrupted solutions, a clear
message for infeasible settings, sampling and frame conversions; the full flip is a slow test."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optimal_control.backflip.audit import audit_solution
from optimal_control.backflip.config import AIR_PHASE, BackflipConfig, tiny_hop_config
from optimal_control.backflip.sagittal import NR, build_sagittal_model, sagittal_model_for
from optimal_control.backflip.solve import InfeasibleBackflipError, solve_backflip_to
from optimal_control.backflip.trajectory import (
    LIMIT_RATIO_TOL,
    fine_grid_limit_report,
    sample_solution,
    sample_times_s,
    wrench_body_to_world_com,
)
from optimal_control.backflip.transcription import _between_knot_limit_rows, make_grid

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


def test_shin_heights_are_the_training_envs_shin_box(model):
    """The TO's shin heights are the corners of the knee link's collision box in the training
    env's model (mesh-free, fitted primitives): its lowest corner is MuJoCo's distance from that
    box to the floor, standing and in a crouch with the shank tilted forward."""
    import mujoco

    from rl.envs.model import build_physics_model
    from robots.conventions import pin_to_mj_qpos

    mj = build_physics_model()
    data = mujoco.MjData(mj)
    floor = mj.geom("floor").id
    shin = mj.geom("left_knee_link_collision").id
    crouch = model.r_stand()
    crouch[3:6] += np.array([-0.9, 1.6, -0.7])  # hip, knee and ankle pitch
    for r in (model.r_stand(), crouch):
        q, _, _ = model.to_full(r[None], np.zeros((1, NR)), np.zeros((1, NR)))
        data.qpos[:] = pin_to_mj_qpos(q[0])
        mujoco.mj_forward(mj, data)
        distance = mujoco.mj_geomDistance(mj, data, shin, floor, 1.0, np.zeros(6))
        lowest = float(np.min(model.shin_heights(r)))
        assert abs(lowest - distance) < 1e-4, (lowest, distance)
    assert float(np.min(model.shin_heights(model.r_stand()))) > 0.01  # standing: above


def test_shin_clearance_is_a_named_constraint_group(model, tmp_path):
    """Asking the shins to stay higher than they are standing cannot be met: the error names
    the group."""
    high = dataclasses.replace(TINY_HOP, shin_clearance=True, min_shin_height_m=0.05, max_iter=30)
    with pytest.raises(InfeasibleBackflipError, match="shin clearance"):
        solve_backflip_to(high, model, failure_path=tmp_path / "last.npz")


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


def test_effort_limits_are_the_urdfs(model):
    """The TO plans within the URDF's effort limits: 35 Nm at the ankle pitch (not the 50 Nm of
    the two-motor linkage in robots.g1's actuator table)."""
    from robots import g1

    urdf = model.robot.model.effortLimit[model.robot.joint_v_index]
    np.testing.assert_array_equal(model.effort_limit_nm, urdf)
    for name in ("left_ankle_pitch_joint", "waist_pitch_joint"):
        assert model.effort_limit_nm[g1.JOINT_NAMES.index(name)] == pytest.approx(35.0)
    # --actuator-effort-limits: the simulator's force ranges instead (50 N m there)
    sim = sagittal_model_for(BackflipConfig(actuator_effort_limits=True))
    np.testing.assert_array_equal(sim.effort_limit_nm, g1.EFFORT_LIMIT_NM)
    for name in ("left_ankle_pitch_joint", "waist_pitch_joint"):
        assert sim.effort_limit_nm[g1.JOINT_NAMES.index(name)] == pytest.approx(50.0)
    assert sagittal_model_for(BackflipConfig()) is build_sagittal_model()


def test_bernstein_rows_bound_the_interpolant_between_knots():
    """The inner Bernstein control points bound the collocation's cubic position and quadratic
    speed on the whole interval; knots alone do not (a knot-feasible interval overshoots)."""
    rng = np.random.default_rng(1)
    s = np.linspace(0.0, 1.0, 201)[:, None]
    for _ in range(50):
        h = rng.uniform(0.01, 0.05)
        r0, rd0 = rng.normal(size=NR), rng.normal(scale=10.0, size=NR)
        a0, a1 = rng.normal(scale=500.0, size=(2, NR))
        rd1 = rd0 + h / 2 * (a0 + a1)
        r1 = r0 + h * rd0 + h**2 / 6 * (2 * a0 + a1)
        pos, speed = (
            np.asarray(x).reshape(-1, NR - 3)
            for x in _between_knot_limit_rows(
                np.stack([r0, r1], 1), np.stack([rd0, rd1], 1), np.stack([a0, a1], 1), [h]
            )
        )
        t = s * h
        slope = (a1 - a0) / h
        rd_t = (rd0 + a0 * t + slope * t**2 / 2)[:, 3:]
        r_t = (r0 + rd0 * t + a0 * t**2 / 2 + slope * t**3 / 6)[:, 3:]
        hull_r = np.stack([r0[3:], r1[3:], *pos])
        hull_v = np.stack([rd0[3:], rd1[3:], *speed])
        assert np.all(r_t <= hull_r.max(0) + 1e-12) and np.all(r_t >= hull_r.min(0) - 1e-12)
        assert np.all(rd_t <= hull_v.max(0) + 1e-12) and np.all(rd_t >= hull_v.min(0) - 1e-12)
    # speed 1 at both knots, accelerating then decelerating: the peak between them is 1.5
    h, lim = 0.02, 1.0
    rd = np.zeros((NR, 2))
    rd[3:] = lim
    rdd = np.zeros((NR, 2))
    rdd[3:, 0], rdd[3:, 1] = 100.0, -100.0
    _, speed = _between_knot_limit_rows(np.zeros((NR, 2)), rd, rdd, [h])
    assert np.all(np.asarray(speed) > lim)  # the constraint sees what the knots miss


def test_torque_rows_keep_the_margin(hop):
    """Knot and midpoint torque rows are bounded by (1 - margin) x alpha x tau_max."""
    tr = hop.transcription
    (a, b) = next((a, b) for name, a, b in tr.groups if name.startswith("torque limits"))
    assert tr.ubg[a:b].max() == pytest.approx(1.0 - TINY_HOP.torque_limit_margin)
    names = [name for name, _, _ in tr.groups]
    assert any("position limits between knots" in name for name in names)
    assert any("speed limits between knots" in name for name in names)
    with pytest.raises(ValueError, match="torque_limit_margin"):
        BackflipConfig(torque_limit_margin=1.0).validate()


def test_torque_refinement_tightens_only_the_overshooting_interval(hop, model):
    """The refinement re-solve tightens the knot and midpoint torque rows of an interval whose
    1 kHz interpolant exceeds the bound, on that joint only, by the overshoot (+ the target)."""
    from optimal_control.backflip.solve import (
        TORQUE_REFINE_TARGET,
        refine_torque_bounds,
        torque_overshoot,
    )

    tr = hop.transcription
    over = torque_overshoot(tr, hop.solution, model)
    assert over.shape == (tr.grid.num_intervals, 29)
    limits = fine_grid_limit_report(hop.solution, tr.grid, model)
    moved_max = (over + tr.torque_limit_fraction).max()
    assert moved_max == pytest.approx(limits["effort"]["max_ratio"], abs=1e-9)
    fake = np.full_like(over, -1.0)
    fake[2, 3] = 0.05
    lbg, ubg, count = refine_torque_bounds(tr, tr.lbg, tr.ubg, fake)
    assert count == 1
    name, a, b = next(g for g in tr.groups if g[0].startswith("torque limits"))
    cut = (tr.ubg[a:b] - ubg[a:b]).reshape(-1, 29)
    hit = (tr.torque_sample_u >= 2) & (tr.torque_sample_u <= 3)
    assert hit.sum() == 3  # knots 2 and 3 and the midpoint of interval 2
    np.testing.assert_allclose(cut[hit, 3], 2 * 0.05 + TORQUE_REFINE_TARGET, atol=1e-12)
    assert np.count_nonzero(cut) == 3
    np.testing.assert_allclose((lbg[a:b] - tr.lbg[a:b]).reshape(-1, 29)[hit, 3], cut[hit, 3])
    # the cut is stored with a solution and re-applied to a warm start's problem
    from optimal_control.backflip.solve import apply_torque_cut, torque_cut

    stored = torque_cut(tr, ubg)
    lbg2, ubg2 = apply_torque_cut(tr, stored)
    np.testing.assert_allclose(ubg2, ubg, atol=1e-15)
    np.testing.assert_allclose(lbg2, lbg, atol=1e-15)


def test_solution_file_keeps_the_torque_cut(hop, tmp_path):
    """A refined solution's torque cut survives the npz round trip (a warm start re-applies it);
    a file without one (older solutions) still loads."""
    from optimal_control.backflip.solve import load_solution, save_solution

    cut = np.zeros((len(hop.transcription.torque_sample_u), 29))
    cut[1, 3] = 0.02
    sol = dataclasses.replace(hop.solution, torque_cut=cut)
    back = load_solution(save_solution(sol, tmp_path / "a.npz"), "test")
    np.testing.assert_array_equal(back.torque_cut, cut)
    plain = dataclasses.replace(hop.solution, torque_cut=None)
    assert load_solution(save_solution(plain, tmp_path / "b.npz"), "test").torque_cut is None


def test_quarter_point_torque_rows(model):
    """--quarter-point-torques adds two torque samples per interval (MX build: seconds)."""
    from optimal_control.backflip.transcription import build_transcription

    cfg = dataclasses.replace(TINY_HOP, symbolic="MX", quarter_point_torques=True)
    tr = build_transcription(model, cfg)
    n = tr.grid.num_knots
    assert len(tr.torque_sample_u) == n + 3 * (n - 1)
    name, a, b = next(g for g in tr.groups if g[0].startswith("torque limits"))
    assert b - a == 29 * len(tr.torque_sample_u)
    assert np.isclose(tr.torque_sample_u, 0.25).sum() == 1


def test_samples_end_at_the_final_knot(hop, model):
    """The artifact's uniform samples end on the final knot (the landed rest pose); the MuJoCo
    sampling keeps its exact step instead."""
    grid = make_grid(TINY_HOP)
    sol = hop.solution
    t_end = sol.knot_times_s(grid)[-1]
    flip = sample_solution(sol, grid, model, 50.0)
    assert flip.time_s[-1] == pytest.approx(t_end, abs=1e-12)
    np.testing.assert_allclose(flip.r[-1], sol.r[-1], atol=1e-9)
    assert flip.dt_s <= 1.0 / 50.0 + 1e-12
    np.testing.assert_allclose(np.diff(flip.time_s), flip.dt_s, atol=1e-12)
    flip.to_reference()  # uniform: the Reference accepts it
    sim = sample_solution(sol, grid, model, 200.0, through_end=False)
    assert sim.dt_s == pytest.approx(0.005, abs=1e-15) and sim.time_s[-1] <= t_end
    assert sample_times_s(0.1, 10.0)[-1] == pytest.approx(0.1)
    assert len(sample_times_s(0.1, 10.0)) == 2
    assert len(sample_times_s(0.105, 10.0)) == 3


def test_hop_is_within_the_limits_between_knots(hop, model):
    limits = fine_grid_limit_report(hop.solution, make_grid(TINY_HOP), model)
    assert limits["within_limits"], limits
    assert limits["effort"]["max_ratio"] <= 1.0 + LIMIT_RATIO_TOL


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
    # within the URDF's effort, speed and position limits between the knots too (1 kHz)
    limits = fine_grid_limit_report(result.solution, result.transcription.grid, model)
    assert limits["within_limits"], limits
    flip = sample_solution(result.solution, result.transcription.grid, model, 50.0)
    assert flip.time_s[-1] == pytest.approx(
        result.solution.knot_times_s(result.transcription.grid)[-1], abs=1e-12
    )


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
    flip = sample_solution(hop.solution, grid, model, 200.0, through_end=False)
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

    flip = sample_solution(hop.solution, make_grid(TINY_HOP), model, 200.0, through_end=False)
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


def _solution_arrays_equal(a, b) -> None:
    for name in ("r", "rd", "rdd", "wrench_b", "force_n", "durations_s", "wrench_mid_b"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_cached_solution_of_the_same_problem_is_reused_without_a_solver(hop, model, tmp_path):
    """A cache file of this very problem is re-checked against the problem's constraints and
    reused as it is (no solver build, no IPOPT); a solution that does not meet them is not."""
    from optimal_control.backflip.solve import (
        cache_path,
        load_cached_solution,
        reuse_solution,
        save_solution,
    )

    cfg = dataclasses.replace(TINY_HOP, cache_dir=str(tmp_path))
    sol = load_cached_solution(save_solution(hop.solution, cache_path(cfg), cfg), cfg)
    reused = reuse_solution(cfg, sol, model)
    assert reused is not None and reused.reused_cached_solution and reused.warm_started
    assert reused.success and reused.total_iterations == 0
    assert reused.stats_dict()["reused_cached_solution"]
    _solution_arrays_equal(reused.solution, hop.solution)
    assert reused.max_violation == pytest.approx(hop.max_violation, abs=1e-9)
    moved = dataclasses.replace(sol, r=sol.r.copy())
    moved.r[3, 0] += 1e-3  # breaks the collocation rows of two intervals
    assert reuse_solution(cfg, moved, model) is None


def test_stale_or_corrupt_cache_files_are_refused(hop, tmp_path):
    """A cache file is reused only for the problem (full key) and tolerance it was solved for:
    another problem's file under this name, a file without a key (a solution.npz copied in) or
    one solved to a looser tol is stale; junk is corrupt (a plain ValueError)."""
    from optimal_control.backflip.solve import (
        StaleCacheError,
        cache_path,
        load_cached_solution,
        problem_key,
        save_solution,
    )

    cfg = dataclasses.replace(TINY_HOP, cache_dir=str(tmp_path))
    path = cache_path(cfg)
    assert path.name == f"backflip_{problem_key(cfg)[:12]}.npz"
    other = dataclasses.replace(cfg, torque_scale=0.9)
    assert problem_key(other) != problem_key(cfg)
    assert problem_key(dataclasses.replace(cfg, tol=1e-8, print_level=5)) == problem_key(cfg)
    for writer, needle in (
        (other, "another problem"),
        (None, "another problem"),
        (dataclasses.replace(cfg, tol=1e-4), "looser"),
    ):
        save_solution(hop.solution, path, writer)
        with pytest.raises(StaleCacheError, match=needle):
            load_cached_solution(path, cfg)
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(ValueError, match="not an .npz") as err:
        load_cached_solution(path, cfg)
    assert not isinstance(err.value, StaleCacheError)


_REUSE_SCRIPT = """
import dataclasses, json, sys
from optimal_control.backflip.config import tiny_hop_config
from optimal_control.backflip.pipeline import BackflipOracleConfig, OutputConfig, solve_backflip
cfg = dataclasses.replace(tiny_hop_config(), max_iter=200, cache_dir=sys.argv[1])
oracle = BackflipOracleConfig(
    alphas=(1.0,), novice_alpha=1.0, video=False, progress=False, out=sys.argv[2]
)
art, folder, report = solve_backflip(cfg, oracle, out_cfg=OutputConfig(playback=False))
print(json.dumps({"solver": report["solver"], "eta0": art.eta0.tolist()}))
"""


def test_a_fresh_process_reuses_the_cache_and_ships_the_same_solution(hop, tmp_path):
    """``solve-backflip`` in a new process with the cache of its problem present builds no
    solver and writes exactly the cached solution into the artifact."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from optimal_control.backflip.solve import cache_path, load_solution, save_solution

    cfg = dataclasses.replace(TINY_HOP, cache_dir=str(tmp_path / "cache"))
    save_solution(hop.solution, cache_path(cfg), cfg)
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run(
        [sys.executable, "-c", _REUSE_SCRIPT, cfg.cache_dir, str(tmp_path / "art")],
        cwd=root,
        capture_output=True,
        text=True,
        check=True,
    )
    solver = json.loads(out.stdout.strip().splitlines()[-1])["solver"]
    assert solver["reused_cached_solution"] and solver["total_iterations"] == 0, solver
    assert solver["warm_start_from"] == str(cache_path(cfg))
    shipped = load_solution(tmp_path / "art" / "solution.npz", "artifact solution")
    _solution_arrays_equal(shipped, hop.solution)


@pytest.mark.slow
def test_reused_cache_gives_the_eta0_of_a_warm_re_solve(tmp_path):
    """The reused cached solution and a warm re-solve from it (a freshly built solver) agree:
    same eta0 to the QP's tolerance, the same solution to IPOPT's; a stale cache file is a miss
    with a warning."""
    from optimal_control.backflip.pipeline import BackflipOracleConfig, OutputConfig, solve_backflip
    from optimal_control.backflip.solve import cache_path, save_solution

    cfg = dataclasses.replace(TINY_HOP, cache_dir=str(tmp_path / "cache"))
    other = dataclasses.replace(cfg, torque_scale=0.9)
    save_solution(solve_backflip_to(cfg, build_sagittal_model()).solution, cache_path(cfg), other)

    def run(name, **out):
        oracle = BackflipOracleConfig(
            alphas=(1.0,), novice_alpha=1.0, video=False, progress=False, out=str(tmp_path / name)
        )
        return solve_backflip(cfg, oracle, out_cfg=OutputConfig(playback=False, **out))

    with pytest.warns(UserWarning, match="stale cache file"):
        cold, _, rep = run("cold")
    assert not rep["solver"]["warm_started"]
    reused, _, rep = run("reused")
    assert rep["solver"]["reused_cached_solution"]
    resolved, _, rep = run("resolved", reuse_cached_solution=False)
    assert rep["solver"]["warm_started"] and not rep["solver"]["reused_cached_solution"]
    # same solution; the novice QPs after it agree to their round-off (not bit for bit)
    np.testing.assert_allclose(reused.eta0, cold.eta0, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(resolved.eta0, reused.eta0, rtol=0.02, atol=0.5)
