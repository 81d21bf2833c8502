"""Audit of a backflip solution, in numbers computed independently of the NLP (Pinocchio).

Every solution is audited before it is written as an artifact:

* dynamics: Pinocchio RNEA with the contact forces, base rows against the pelvis wrench, joint rows
  against alpha * effort limit;
* integration: the trapezoidal collocation equations at the solved knots;
* contacts (complementarity): force only where the soles are on the ground, unilateral and inside
  the friction pyramid, soles at rest and in place while loaded, no penetration in the air;
* energy: the change of mechanical energy E = T + V against the work of the joint torques, the
  pelvis wrench and the contact forces (trapezoidal quadrature of the power at the knots);
  contacts must do no net positive work (the prototype's failure: +198 J from 3.6 J of joints);
* task: a full -2 pi pitch turn, landing upright and at rest.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pinocchio as pin

from optimal_control.backflip.config import PHASE_NAMES, BackflipConfig
from optimal_control.backflip.sagittal import SagittalModel
from optimal_control.backflip.transcription import Grid, Solution, make_grid
from optimal_control.validation import require_finite_fields
from robots import g1


@dataclass(frozen=True)
class AuditConfig:
    """Acceptance limits of the audit."""

    dynamics_tol: float = 1e-3  # max base-row residual of the inverse dynamics [N, Nm]
    torque_tol: float = 1e-3  # allowed excess over alpha * effort limit [effort share]
    integration_tol: float = 1e-5  # max collocation residual [m, rad, m/s, rad/s]
    contact_tol_n: float = 1e-3  # max force outside the cone or off the ground [N]
    sole_speed_tol_m_s: float = 1e-4  # max sole point speed while loaded [m/s]
    sole_drift_tol_m: float = 0.0025  # max sole displacement while loaded [m]
    energy_tol_fraction: float = 0.03  # energy balance error allowed, fraction of gross work [-]
    energy_tol_j: float = 5.0  # energy balance error always allowed [J]
    max_contact_work_j: float = 1.0  # contacts may not do more positive work than this [J]
    final_pitch_tol_rad: float = 1e-3  # final pitch within this of -2 pi [rad]

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field and its flag."""
        require_finite_fields(self)


@dataclass
class Check:
    """One audited quantity."""

    value: float  # measured value
    limit: float  # acceptance limit
    passed: bool  # value within limit
    note: str = ""  # what is measured, units


@dataclass
class AuditReport:
    """Audit result: every check, the energy ledger per phase, and the verdict."""

    checks: dict[str, Check]
    energy_per_phase: dict[str, dict[str, float]]  # phase -> dE, joint, wrench, contact work [J]
    energy_total: dict[str, float]  # the same over the whole motion [J]
    extra: dict[str, float] = field(default_factory=dict)  # take-off speed, apex, flight time...

    @property
    def passed(self) -> bool:
        """All checks passed."""
        return all(c.passed for c in self.checks.values())

    def failures(self) -> list[str]:
        """Names and values of the failed checks."""
        return [
            f"{k}: {c.value:.4g} (limit {c.limit:.4g}; {c.note})"
            for k, c in self.checks.items()
            if not c.passed
        ]

    def to_dict(self) -> dict:
        """JSON-ready report."""
        checks = {k: {**asdict(c), "passed": bool(c.passed)} for k, c in self.checks.items()}
        return {
            "passed": bool(self.passed),
            "checks": checks,
            "energy_per_phase_j": self.energy_per_phase,
            "energy_total_j": self.energy_total,
            "extra": self.extra,
        }


def _contact_fext(model: SagittalModel, data: pin.Data, q: np.ndarray, force: np.ndarray):
    """Pinocchio external forces (per joint, local) of the heel/toe forces on both soles."""
    robot = model.robot
    fext = [pin.Force.Zero() for _ in range(robot.model.njoints)]
    half = g1.SOLE_HALF_LENGTH_M
    for side in g1.SOLE_FRAMES:
        fid = robot.frame_ids[side]
        joint = robot.model.frames[fid].parentJoint
        total = pin.Force.Zero()
        for k, x in enumerate((-half, half)):
            p_w = data.oMf[fid].act(np.array([x, 0.0, 0.0]))
            f_w = np.array([force[2 * k], 0.0, force[2 * k + 1]])
            total += pin.Force(f_w, np.cross(p_w, f_w))
        fext[joint] = data.oMi[joint].actInv(total)
    return fext


def audit_solution(
    sol: Solution,
    cfg: BackflipConfig,
    model: SagittalModel,
    acfg: AuditConfig = AuditConfig(),
    grid: Grid | None = None,
) -> AuditReport:
    """Audit ``sol`` (see the module docstring); never raises on a bad solution, reports it."""
    grid = grid or make_grid(cfg)
    robot = model.robot
    pmodel = robot.model
    data = pmodel.createData()
    n = grid.num_knots
    q, v, a = model.to_full(sol.r, sol.rd, sol.rdd)
    dt = sol.dt_per_interval(grid)
    fk = set(grid.force_knots().tolist())
    base_res = np.zeros(n)
    torque_excess = np.zeros(n)
    tau = np.zeros((n, pmodel.nv))
    energy = np.zeros(n)
    sole_v = np.zeros((n, 2, 2))  # knot, heel/toe, (x, z) world velocity
    sole_p = np.zeros((n, 2, 2))
    for k in range(n):
        pin.forwardKinematics(pmodel, data, q[k], v[k])
        pin.updateFramePlacements(pmodel, data)
        fext = _contact_fext(model, data, q[k], sol.force_n[k])
        tau[k] = pin.rnea(pmodel, data, q[k], v[k], a[k], fext)
        base_res[k] = np.abs(tau[k, :6] - sol.wrench_b[k]).max()
        torque_excess[k] = np.max(np.abs(tau[k, 6:]) / model.effort_limit_nm - cfg.torque_scale)
        energy[k] = pin.computeKineticEnergy(pmodel, data, q[k], v[k]) + pin.computePotentialEnergy(
            pmodel, data, q[k]
        )
        fid = robot.frame_ids[g1.SOLE_FRAMES[0]]
        for j, x in enumerate((-g1.SOLE_HALF_LENGTH_M, g1.SOLE_HALF_LENGTH_M)):
            pt = np.array([x, 0.0, 0.0])
            sole_p[k, j] = data.oMf[fid].act(pt)[[0, 2]]
            vel = pin.getFrameVelocity(pmodel, data, fid, pin.LOCAL_WORLD_ALIGNED)
            p_rel = data.oMf[fid].rotation @ pt
            sole_v[k, j] = (vel.linear + np.cross(vel.angular, p_rel))[[0, 2]]

    # integration residuals of the trapezoidal collocation
    h = dt[:, None]
    res_v = sol.rd[1:] - sol.rd[:-1] - h / 2 * (sol.rdd[:-1] + sol.rdd[1:])
    res_p = sol.r[1:] - sol.r[:-1] - h * sol.rd[:-1] - h**2 / 6 * (2 * sol.rdd[:-1] + sol.rdd[1:])
    integration = float(max(np.abs(res_v).max(), np.abs(res_p).max()))

    # contacts
    fx, fz = sol.force_n[:, 0::2], sol.force_n[:, 1::2]
    mu = cfg.friction_coefficient
    cone = float(max(np.maximum(-fz, 0).max(), np.maximum(np.abs(fx) - mu * fz, 0).max()))
    off = [k for k in range(n) if k not in fk]
    force_off_ground = float(np.abs(sol.force_n[off]).max()) if off else 0.0
    loaded = sorted(fk)
    loaded_speed = float(np.abs(sole_v[loaded]).max())
    pre = [k for k in range(grid.takeoff_knot + 1)]
    post = list(range(grid.touchdown_knot, n))
    drift = max(
        np.abs(sole_p[pre] - sole_p[0]).max(),
        np.abs(sole_p[post] - sole_p[grid.touchdown_knot]).max(),
    )
    air = list(range(grid.takeoff_knot + 1, grid.touchdown_knot))
    floor_z = float(sole_p[0, :, 1].min())
    penetration = float(max(0.0, floor_z - sole_p[air, :, 1].min() - 1e-9)) if air else 0.0

    # energy ledger: power at the knots, trapezoidal quadrature over each interval
    p_joint = np.einsum("ij,ij->i", tau[:, 6:], v[:, 6:])
    p_wrench = np.einsum("ij,ij->i", sol.wrench_b, v[:, :6])
    # both soles carry the same heel/toe forces and move alike (symmetric motion)
    p_contact = 2.0 * np.einsum("kjc,kjc->k", sol.force_n.reshape(n, 2, 2), sole_v)

    def work(p):
        return dt / 2 * (p[:-1] + p[1:])

    w_j, w_w, w_c = work(p_joint), work(p_wrench), work(p_contact)
    d_e = np.diff(energy)
    phase = grid.phase_of_interval
    per_phase = {}
    for i, name in enumerate(PHASE_NAMES):
        m = phase == i
        per_phase[name] = {
            "delta_energy": float(d_e[m].sum()),
            "joint_work": float(w_j[m].sum()),
            "wrench_work": float(w_w[m].sum()),
            "contact_work": float(w_c[m].sum()),
            "balance_error": float((d_e - w_j - w_w - w_c)[m].sum()),
        }
    total = {
        "delta_energy": float(d_e.sum()),
        "joint_work": float(w_j.sum()),
        "wrench_work": float(w_w.sum()),
        "contact_work": float(w_c.sum()),
        "balance_error": float((d_e - w_j - w_w - w_c).sum()),
        "gross_joint_work": float(np.abs(w_j).sum()),
        "positive_joint_work": float(np.maximum(w_j, 0).sum()),
    }
    gross = total["gross_joint_work"] + float(np.abs(w_w).sum())
    energy_limit = max(acfg.energy_tol_j, acfg.energy_tol_fraction * gross)
    worst_interval = float(np.abs(d_e - w_j - w_w - w_c).max())

    pitch_n = sol.r[-1, 2]
    checks = {
        "dynamics residual (base rows vs pelvis wrench)": Check(
            float(base_res.max()), acfg.dynamics_tol, base_res.max() <= acfg.dynamics_tol, "N, Nm"
        ),
        "torque over alpha*tau_max": Check(
            float(torque_excess.max()),
            acfg.torque_tol,
            torque_excess.max() <= acfg.torque_tol,
            "max |tau|/tau_max - alpha",
        ),
        "integration residual": Check(
            integration, acfg.integration_tol, integration <= acfg.integration_tol, "m, rad, /s"
        ),
        "friction cone / unilateral violation": Check(
            cone, acfg.contact_tol_n, cone <= acfg.contact_tol_n, "N"
        ),
        "force off the ground (complementarity)": Check(
            force_off_ground, acfg.contact_tol_n, force_off_ground <= acfg.contact_tol_n, "N"
        ),
        "loaded sole speed (complementarity)": Check(
            loaded_speed, acfg.sole_speed_tol_m_s, loaded_speed <= acfg.sole_speed_tol_m_s, "m/s"
        ),
        "loaded sole drift": Check(
            float(drift), acfg.sole_drift_tol_m, drift <= acfg.sole_drift_tol_m, "m"
        ),
        "sole penetration in the air": Check(penetration, 1e-4, penetration <= 1e-4, "m"),
        "energy balance error": Check(
            abs(total["balance_error"]),
            energy_limit,
            abs(total["balance_error"]) <= energy_limit,
            "J, |dE - joint - wrench - contact work|",
        ),
        "contact positive work": Check(
            total["contact_work"],
            acfg.max_contact_work_j,
            total["contact_work"] <= acfg.max_contact_work_j,
            "J, net work done by the ground",
        ),
        "final pitch error": Check(
            abs(pitch_n - cfg.turn_rad),
            acfg.final_pitch_tol_rad,
            abs(pitch_n - cfg.turn_rad) <= acfg.final_pitch_tol_rad,
            "rad from the turn (-2 pi for a backflip)",
        ),
        "final speed": Check(
            float(np.abs(sol.rd[-1]).max()), 1e-4, np.abs(sol.rd[-1]).max() <= 1e-4, "m/s, rad/s"
        ),
    }
    k0, k1 = grid.takeoff_knot, grid.touchdown_knot
    com_fn = model.dyn.com
    com = np.asarray(com_fn.map(n)(q.T)).T
    times = sol.knot_times_s(grid)
    extra = {
        "worst_interval_energy_error_j": worst_interval,
        "takeoff_time_s": float(times[k0]),
        "touchdown_time_s": float(times[k1]),
        "flight_time_s": float(times[k1] - times[k0]),
        "takeoff_com_height_m": float(com[k0, 2]),
        "apex_com_height_m": float(com[k0 : k1 + 1, 2].max()),
        "com_rise_m": float(com[k0 : k1 + 1, 2].max() - com[0, 2]),
        "takeoff_pitch_rate_rad_s": float(sol.rd[k0, 2]),
        "max_wrench_force_n": float(np.abs(sol.wrench_b[:, :3]).max()),
        "max_wrench_torque_nm": float(np.abs(sol.wrench_b[:, 3:]).max()),
        "max_joint_speed_fraction": float(np.max(np.abs(sol.rd[:, 3:]) / model.velocity_limit[3:])),
    }
    return AuditReport(checks, per_phase, total, extra)
