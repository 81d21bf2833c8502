"""Clips as retargeting produces them: robust ground, contact hysteresis, plausibility report."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from optimal_control.bounds import BoundRule, eta0_per_phase
from optimal_control.motion_clip import (
    ClipConfig,
    ClipError,
    ClipPlausibilityWarning,
    despike,
    estimate_ground_m,
    infer_contacts,
    load_motion_clip_with_report,
)
from optimal_control.synthetic_clips import RetargetArtefacts, retargeted_rows
from optimal_control.walk import WalkConfig, plan_walk
from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig

WEIGHT_N = 33.34 * 9.81  # the G1's weight [N]


@pytest.fixture(scope="module")
def walk_ref():
    """A clean 5 s placo walk at 0.4 m/s."""
    return plan_walk(WalkConfig(vx=0.4, duration=5.0)).reference


@pytest.fixture(scope="module")
def retargeted_csv(walk_ref, tmp_path_factory):
    """The walk as a retargeted 30 fps clip: hover, drift, penetration outliers, noise."""
    path = tmp_path_factory.mktemp("clip") / "retargeted.csv"
    np.savetxt(path, retargeted_rows(walk_ref, RetargetArtefacts(seed=3)), delimiter=",")
    return path


def test_ground_estimate_ignores_single_frame_penetrations():
    heights = np.full((100, 2), 0.02)
    heights[50, 0] = -0.06  # one corner snapped through the floor
    assert estimate_ground_m(heights) == pytest.approx(0.02)
    assert heights.min() == pytest.approx(-0.06)  # what the former shift used


def test_despike_removes_one_frame_outliers_but_not_fast_limbs():
    t = np.arange(90) / 30.0
    rows = np.zeros((90, 36))
    rows[:, 6] = 1.0
    rows[:, 2] = 0.78
    rows[:, 7] = 0.6 * np.sin(2 * np.pi * 2.0 * t)  # a 2 Hz joint swing of 0.6 rad
    clean = rows.copy()
    rows[40, 2] -= 0.06
    out, replaced = despike(rows)
    assert replaced == 1
    np.testing.assert_allclose(out, clean, atol=1e-12)


def test_contacts_have_hysteresis(g1_pin):
    dt = 0.02
    q = np.tile(g1_pin.q_stand, (60, 1))
    # Hovering at 5 cm after a planted start stays in contact (below the 7 cm release height)...
    q[10:30, 2] += 0.05
    # ...a real lift to 10 cm leaves it.
    q[40:50, 2] += 0.10
    contacts = infer_contacts(q, dt, support_fallback=False)
    assert contacts[:30].all()
    assert not contacts[41:49].any()


def test_retargeted_clip_gives_a_plausible_schedule_and_eta0(retargeted_csv):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClipPlausibilityWarning)
        ref, report = load_motion_clip_with_report(retargeted_csv)
    assert report["no_contact_share"] < 0.10
    assert report["despiked_samples"] >= 1
    prof = WrenchQP(WrenchQPConfig(alpha=0.5)).solve_reference(ref)
    eta0 = eta0_per_phase(prof.wrench_w, ref.phase, 1, BoundRule(), prof.solved)
    assert eta0[0, 2] < 0.3 * WEIGHT_N, eta0


def test_former_pipeline_calls_the_same_clip_flying(retargeted_csv):
    former = ClipConfig(
        despike=False,
        ground_percentile=0.0,  # the single lowest corner
        support_fallback=False,
        contact_height_m=0.03,
        contact_release_height_m=0.03,
        contact_release_speed_m_s=0.4,
        max_no_contact_share=1.0,
    )
    with pytest.warns(ClipPlausibilityWarning, match="no sole in contact"):
        _, report = load_motion_clip_with_report(retargeted_csv, former)
    assert report["no_contact_share"] > 0.5


def test_implausible_clips_are_refused(tmp_path, walk_ref):
    rows = retargeted_rows(walk_ref, RetargetArtefacts(seed=1))
    glitch = rows.copy()
    glitch[20, 0] = 1e12
    np.savetxt(tmp_path / "glitch.csv", glitch, delimiter=",")
    with pytest.raises(ClipError, match="m/s"):
        load_motion_clip_with_report(tmp_path / "glitch.csv")
    flying = rows.copy()
    flying[:, 2] += 0.5  # half a metre above the floor: only a full float would "fit"
    np.savetxt(tmp_path / "flying.csv", flying, delimiter=",")
    cfg = ClipConfig(ground_to_lowest_sole=False)
    with pytest.raises(ClipError, match="no sole in contact"):
        load_motion_clip_with_report(tmp_path / "flying.csv", cfg)


def test_plausibility_report_is_stored_in_the_artifact(retargeted_csv, tmp_path):
    from optimal_control.artifact import OracleArtifact
    from optimal_control.oracle import OracleConfig, solve_dance

    cfg = OracleConfig(alphas=(1.0, 0.5), video=False, progress=False, out=str(tmp_path / "a"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClipPlausibilityWarning)
        _, folder = solve_dance(cfg=cfg, clip=str(retargeted_csv), clip_cfg=ClipConfig())
    report = OracleArtifact.load(folder).extra_summary["clip_plausibility"]
    assert report["no_contact_share"] < 0.10
    assert 0.0 <= report["unaided_share_alpha_1"] <= 1.0
    assert report["largest_base_jump_m"] > 0.0 and "problems" in report
