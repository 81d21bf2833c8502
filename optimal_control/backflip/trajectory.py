"""Sampling a solved backflip at a fixed rate, and its conversion to the oracle's conventions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optimal_control.backflip.config import AIR_PHASE, PHASE_NAMES
from optimal_control.backflip.sagittal import SagittalModel
from optimal_control.backflip.transcription import Grid, Solution
from optimal_control.reference import Reference
from optimal_control.wrench_qp import pelvis_com_offset_m
from robots.conventions import quat_wxyz_to_matrix, quat_xyzw_to_wxyz


@dataclass
class SampledFlip:
    """A solution sampled at a uniform rate (T frames), full Pinocchio layout.

    time_s (T,); r, rd (T, NR); q (T, 36); v, a (T, 35); phase (T,) int; tau_nm (T, 29) joint
    torques; force_n (T, 4) heel/toe (fx, fz) per foot; wrench_b (T, 6) TO pelvis wrench in the
    pelvis frame about its origin; wrench_w (T, 6) the same as world force / torque at the pelvis
    CoM (MuJoCo ``xfrc_applied``); dt_s.
    """

    time_s: np.ndarray
    r: np.ndarray
    rd: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    phase: np.ndarray
    tau_nm: np.ndarray
    force_n: np.ndarray
    wrench_b: np.ndarray
    wrench_w: np.ndarray
    dt_s: float

    def to_reference(self, name: str = "backflip") -> Reference:
        """The oracle :class:`Reference` (contacts: both soles except in Air)."""
        stance = self.phase != AIR_PHASE
        ref = Reference(
            time_s=self.time_s,
            q=self.q,
            v=self.v,
            a=self.a,
            contacts=np.stack([stance, stance], axis=1),
            phase=self.phase.astype(int),
            phase_names=PHASE_NAMES,
            dt=self.dt_s,
            name=name,
        )
        return ref.validate()


def wrench_body_to_world_com(q: np.ndarray, wrench_b: np.ndarray, lever_b: np.ndarray):
    """Pelvis wrench (T, 6) in the pelvis frame about its origin -> world force and world torque
    about the pelvis CoM (T, 6), for configurations q (T, 36)."""
    rot = quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q[:, 3:7]))
    f_w = np.einsum("tij,tj->ti", rot, wrench_b[:, :3])
    m_origin_w = np.einsum("tij,tj->ti", rot, wrench_b[:, 3:])
    lever_w = np.einsum("tij,j->ti", rot, lever_b)
    return np.concatenate([f_w, m_origin_w - np.cross(lever_w, f_w)], axis=1)


LIMIT_RATIO_TOL = 1e-3
"""Effort and speed ratios up to 1 + this count as within the limits (the audit's torque_tol)."""


def sample_times_s(duration_s: float, rate_hz: float, through_end: bool = True) -> np.ndarray:
    """Uniform sample times over [0, duration_s].

    ``through_end``: the last sample is the end (the final knot); the step is the largest
    ``duration_s / M`` not above ``1 / rate_hz`` (the rate is at least ``rate_hz``). Otherwise the
    step is exactly ``1 / rate_hz`` (a simulator's fixed step) and the last sample is the last
    multiple of it not after the end.
    """
    if rate_hz <= 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz}.")
    if through_end:
        steps = max(1, int(np.ceil(duration_s * rate_hz - 1e-6)))
        return np.linspace(0.0, duration_s, steps + 1)
    return np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)


def sample_solution(
    sol: Solution, grid: Grid, model: SagittalModel, rate_hz: float, through_end: bool = True
) -> SampledFlip:
    """Sample ``sol`` at (at least) ``rate_hz`` with the collocation's own interpolant
    (acceleration linear, velocity quadratic, position cubic in each interval); forces linear
    (zero inside the Air phase), the wrench quadratic through its knot and midpoint values,
    torques from the inverse dynamics of the sampled state. Sample times as in
    :func:`sample_times_s`: by default the last sample is the final knot (the landed rest pose);
    ``through_end=False`` keeps the step at exactly ``1 / rate_hz`` (MuJoCo playback)."""
    t_knots = sol.knot_times_s(grid)
    times = sample_times_s(float(t_knots[-1]), rate_hz, through_end)
    dt = float(times[1] - times[0]) if len(times) > 1 else 1.0 / rate_hz
    k = np.clip(np.searchsorted(t_knots, times, side="right") - 1, 0, grid.num_intervals - 1)
    h = (t_knots[k + 1] - t_knots[k])[:, None]
    s = (times - t_knots[k])[:, None]
    a0, a1 = sol.rdd[k], sol.rdd[k + 1]
    slope = (a1 - a0) / h
    rdd = a0 + slope * s
    rd = sol.rd[k] + a0 * s + slope * s**2 / 2
    r = sol.r[k] + sol.rd[k] * s + a0 * s**2 / 2 + slope * s**3 / 6
    lam = s / h
    force = (1 - lam) * sol.force_n[k] + lam * sol.force_n[k + 1]
    phase = grid.phase_of_interval[k]
    force[phase == AIR_PHASE] = 0.0
    # quadratic through the knot and midpoint wrenches
    wrench_b = (
        sol.wrench_b[k] * (1 - lam) * (1 - 2 * lam)
        + 4 * sol.wrench_mid_b[k] * lam * (1 - lam)
        + sol.wrench_b[k + 1] * lam * (2 * lam - 1)
    )
    q, v, a = model.to_full(r, rd, rdd)
    n = len(times)
    tau = np.asarray(model.inverse_dynamics.map(n)(r.T, rd.T, rdd.T, force.T)).T
    lever = pelvis_com_offset_m(model.robot)
    return SampledFlip(
        time_s=times,
        r=r,
        rd=rd,
        q=q,
        v=v,
        a=a,
        phase=phase,
        tau_nm=tau[:, 6:],
        force_n=force,
        wrench_b=wrench_b,
        wrench_w=wrench_body_to_world_com(q, wrench_b, lever),
        dt_s=dt,
    )


def fine_grid_limit_report(
    sol: Solution, grid: Grid, model: SagittalModel, rate_hz: float = 1000.0
) -> dict:
    """Largest effort, speed and position ratio to the URDF limits on a fine grid (JSON-ready).

    ``within_limits``: effort and speed ratios <= 1 + :data:`LIMIT_RATIO_TOL`, no position beyond
    the range (share <= 1e-6).

    The solution is sampled at ``rate_hz`` with the collocation's own interpolant
    (:func:`sample_solution`, torques from the inverse dynamics of each sample), so excursions
    *between* knots count. Ratios: |tau| / effort limit, |qdot| / URDF speed limit, and for
    positions the excursion beyond the URDF range as a share of the range (0 = within limits),
    each with the joint and time [s] of the worst sample.
    """
    flip = sample_solution(sol, grid, model, rate_hz)
    robot = model.robot
    effort = np.abs(flip.tau_nm) / model.effort_limit_nm
    speed = np.abs(flip.v[:, robot.joint_v_index]) / robot.velocity_limit_rad_s
    joints = flip.q[:, robot.joint_q_index]
    span = robot.position_upper_rad - robot.position_lower_rad
    beyond = np.maximum(robot.position_lower_rad - joints, joints - robot.position_upper_rad)
    position = np.maximum(beyond, 0.0) / span
    from robots import g1

    def worst(ratio: np.ndarray) -> dict:
        t, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        return {
            "max_ratio": float(ratio[t, j]),
            "joint": g1.JOINT_NAMES[j],
            "time_s": float(flip.time_s[t]),
            "phase": PHASE_NAMES[int(flip.phase[t])],
        }

    return {
        "rate_hz": rate_hz,
        "samples": int(flip.time_s.shape[0]),
        "effort": worst(effort),
        "speed": worst(speed),
        "position_beyond_range": worst(position),
        "pelvis_wrench_max_norm_force_n": float(np.linalg.norm(flip.wrench_w[:, :3], axis=1).max()),
        "ratio_tolerance": LIMIT_RATIO_TOL,
        "within_limits": bool(effort.max() <= 1.0 + LIMIT_RATIO_TOL)
        and bool(speed.max() <= 1.0 + LIMIT_RATIO_TOL)
        and bool(position.max() <= 1e-6),
    }
