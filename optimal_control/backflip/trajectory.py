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


def sample_solution(sol: Solution, grid: Grid, model: SagittalModel, rate_hz: float) -> SampledFlip:
    """Sample ``sol`` at ``rate_hz`` with the collocation's own interpolant (acceleration linear,
    velocity quadratic, position cubic in each interval); forces linear (zero inside the Air
    phase), the wrench quadratic through its knot and midpoint values, torques from the inverse
    dynamics of the sampled state."""
    if rate_hz <= 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz}.")
    t_knots = sol.knot_times_s(grid)
    dt = 1.0 / rate_hz
    times = np.arange(0.0, t_knots[-1] + 1e-9, dt)
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
