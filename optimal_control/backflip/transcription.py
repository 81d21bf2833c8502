"""The backflip NLP (direct transcription) and its hand-designed initial guess.

Time grid: the five phases of :mod:`.config` with a fixed number of intervals each and a duration
that is a decision variable (uniform step inside a phase). Knots k = 0..N carry the sagittal state
r_k, rd_k (see :mod:`.sagittal`), an acceleration rdd_k, the pelvis wrench w_k and, at contact
knots, the heel/toe forces f_k. Integration is trapezoidal collocation with a piecewise-linear
acceleration (second order; exact for linear acceleration):

    rd_{k+1} = rd_k + h/2 (rdd_k + rdd_{k+1}),   r_{k+1} = r_k + h rd_k + h^2/6 (2 rdd_k + rdd_{k+1})

Full 3-D inverse dynamics at every knot, tau_k = ID(r_k, rd_k, rdd_k, f_k), gives the generalised
force: its six free-flyer rows must equal w_k (the pelvis wrench, pelvis frame, about the pelvis
origin), its 29 joint rows are the joint torques, bounded by alpha * effort limit.

Contact: the heel and toe velocities are zero at every stance knot, 0..K_to (take-off) and
K_td (touch-down)..N, including the knot that closes push-off, so the contact power f . v_sole is
zero at every knot and contacts can do no work (the prototype's push-off energy leak: a sole fixed by
position only let the last push-off interval inject energy). The take-off knot carries no force (the
ground force ramps to zero as the soles leave). Touch-down is soft: the soles arrive at rest.
A first-order (semi-implicit Euler) scheme was tried first: its per-interval energy error reached
~100 J at the 0.03-0.09 s steps used here, and the optimiser exploited it; the energy audit caught it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from optimal_control.backflip.config import AIR_PHASE, BackflipConfig
from optimal_control.backflip.sagittal import NF, NR, SagittalModel

WRENCH_SCALE = np.array([100.0, 100.0, 100.0, 30.0, 30.0, 30.0])
"""Scale of the pelvis wrench decision variables [N, N, N, Nm, Nm, Nm]."""
FORCE_SCALE_N = 100.0
"""Scale of the contact force decision variables [N]."""


@dataclass(frozen=True)
class Grid:
    """Knot bookkeeping of one configuration."""

    intervals: tuple[int, ...]  # intervals per phase
    phase_of_interval: np.ndarray  # (N,) phase id of each interval
    takeoff_knot: int  # first knot of Air (on the ground, no force)
    touchdown_knot: int  # first knot of Land

    @property
    def num_intervals(self) -> int:
        """N, the number of intervals."""
        return int(sum(self.intervals))

    @property
    def num_knots(self) -> int:
        """N + 1."""
        return self.num_intervals + 1

    def force_knots(self) -> np.ndarray:
        """Knots carrying contact force: stance intervals before take-off, and all of Land."""
        n = self.num_knots
        return np.array([k for k in range(n) if k < self.takeoff_knot or k >= self.touchdown_knot])

    def fixed_sole_knots(self) -> np.ndarray:
        """Knots whose soles are held on the ground."""
        n = self.num_knots
        return np.array([k for k in range(n) if k <= self.takeoff_knot or k >= self.touchdown_knot])

    def phase_of_knot(self) -> np.ndarray:
        """(N + 1,) phase id of each knot (the last knot belongs to Land)."""
        return np.append(self.phase_of_interval, self.phase_of_interval[-1])


def make_grid(cfg: BackflipConfig) -> Grid:
    """Knot bookkeeping for ``cfg``."""
    counts = tuple(p.intervals for p in cfg.phases())
    phase = np.concatenate([np.full(n, i) for i, n in enumerate(counts)])
    takeoff = sum(counts[:3])
    return Grid(counts, phase, takeoff, takeoff + counts[3])


@dataclass
class Solution:
    """A (candidate) backflip trajectory on the knot grid; arrays indexed by knot.

    r, rd, rdd (N+1, NR); wrench_b (N+1, 6) pelvis wrench in the pelvis frame [N, Nm];
    force_n (N+1, NF) heel/toe (fx, fz) per foot, zero where no contact; durations_s (5,);
    wrench_mid_b (N, 6) pelvis wrench at the interval midpoints [N, Nm].
    """

    r: np.ndarray
    rd: np.ndarray
    rdd: np.ndarray
    wrench_b: np.ndarray
    force_n: np.ndarray
    durations_s: np.ndarray
    wrench_mid_b: np.ndarray
    # (blocks, 29) how far the torque refinement tightened each torque-limit row below
    # alpha x tau_max [fraction of tau_max]; None = not refined. Part of the solved problem: a
    # warm start re-applies it, so the warm re-solve solves the same NLP.
    torque_cut: np.ndarray | None = None

    def dt_per_interval(self, grid: Grid) -> np.ndarray:
        """(N,) time step of each interval [s]."""
        steps = self.durations_s / np.asarray(grid.intervals)
        return steps[grid.phase_of_interval]

    def knot_times_s(self, grid: Grid) -> np.ndarray:
        """(N + 1,) time of each knot [s]."""
        return np.concatenate([[0.0], np.cumsum(self.dt_per_interval(grid))])

    def to_npz_dict(self) -> dict[str, np.ndarray]:
        """Arrays for ``np.savez``."""
        cut = {} if self.torque_cut is None else {"torque_cut": self.torque_cut}
        return cut | {
            "r": self.r,
            "rd": self.rd,
            "rdd": self.rdd,
            "wrench_b": self.wrench_b,
            "force_n": self.force_n,
            "durations_s": self.durations_s,
            "wrench_mid_b": self.wrench_mid_b,
        }

    @classmethod
    def from_npz(cls, data) -> Solution:
        """Inverse of :meth:`to_npz_dict` (an ``np.load`` result or a dict)."""
        optional = {"torque_cut"}
        fields = {
            k: np.asarray(data[k], dtype=float)
            for k in cls.__dataclass_fields__
            if k not in optional or k in data
        }
        return cls(**fields)


@dataclass
class Transcription:
    """The NLP of one configuration: solver inputs and packing helpers."""

    cfg: BackflipConfig
    grid: Grid
    nlp: dict  # {"x", "f", "g", "p"} SX
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    groups: list[tuple[str, int, int]]  # (constraint group name, start, stop) rows of g
    unpack: ca.Function  # x -> (r, rd, rdd, w_s, f_s, durations)
    force_knots: np.ndarray
    num_params: int
    # knot-axis position (k + fraction of interval k) of each block of 29 torque-limit rows
    torque_sample_u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    torque_limit_fraction: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # (29,) of tau_max

    def pack(self, sol: Solution) -> np.ndarray:
        """Decision vector x of a :class:`Solution`."""
        fk = self.force_knots
        return np.concatenate(
            [
                sol.r.ravel(),
                sol.rd.ravel(),
                sol.rdd.ravel(),
                (sol.wrench_b / WRENCH_SCALE).ravel(),
                (sol.force_n[fk] / FORCE_SCALE_N).ravel(),
                sol.durations_s,
                (sol.wrench_mid_b / WRENCH_SCALE).ravel(),
            ]
        )

    def solution(self, x: np.ndarray) -> Solution:
        """:class:`Solution` of a decision vector x."""
        r, rd, rdd, w_s, f_s, dur, w_mid = (np.asarray(a) for a in self.unpack(x))
        n = self.grid.num_knots
        force = np.zeros((n, NF))
        force[self.force_knots] = f_s.T * FORCE_SCALE_N
        return Solution(
            r.T.copy(),
            rd.T.copy(),
            rdd.T.copy(),
            w_s.T * WRENCH_SCALE,
            force,
            dur.ravel(),
            w_mid.T * WRENCH_SCALE,
        )


def build_transcription(model: SagittalModel, cfg: BackflipConfig) -> Transcription:
    """Build the NLP of ``cfg``; its parameter p (1,) is the pelvis-wrench weight.

    ``cfg.symbolic = "SX"`` (default) inlines everything into one SX graph: slow to build (the
    exact Hessian of ~140 whole-body RNEAs) but fast per IPOPT iteration. ``"MX"`` maps two SX functions (knot rows, interval rows) over the grid: built
    fast, but each iteration costs more (the times: ``docs/backflip.md``).
    """
    cfg.validate()
    SYM = ca.MX if cfg.symbolic == "MX" else ca.SX  # noqa: N806
    grid = make_grid(cfg)
    phases = cfg.phases()
    n = grid.num_knots
    fk = grid.force_knots()
    r = SYM.sym("r", NR, n)
    rd = SYM.sym("rd", NR, n)
    rdd = SYM.sym("rdd", NR, n)
    w_s = SYM.sym("w", 6, n)
    f_s = SYM.sym("f", NF, len(fk))
    dur = SYM.sym("T", len(phases))
    w_mid = SYM.sym("w_mid", 6, n - 1)
    weight_w = SYM.sym("weight_w")
    x = ca.vertcat(
        ca.vec(r),
        ca.vec(rd),
        ca.vec(rdd),
        ca.vec(w_s),
        ca.vec(f_s),
        dur,
        ca.vec(w_mid),
    )
    # note: ca.vec is column-major, so knot k's r is x[k*NR:(k+1)*NR]: matches (n, NR).ravel()
    unpack = ca.Function("unpack", [x], [r, rd, rdd, w_s, f_s, dur, w_mid])

    g_rows: list[ca.SX] = []
    lbg: list[np.ndarray] = []
    ubg: list[np.ndarray] = []
    groups: list[tuple[str, int, int]] = []
    count = [0]

    def add(name: str, expr: ca.SX, lo, hi) -> None:
        expr = ca.vec(expr)
        size = expr.shape[0]
        g_rows.append(expr)
        lbg.append(np.broadcast_to(np.asarray(lo, dtype=float), (size,)).copy())
        ubg.append(np.broadcast_to(np.asarray(hi, dtype=float), (size,)).copy())
        groups.append((name, count[0], count[0] + size))
        count[0] += size

    alpha = cfg.torque_scale
    effort = model.effort_limit_nm
    stand = model.r_stand()
    p_stand = np.asarray(model.sole_points(stand))
    force_index = {int(k): i for i, k in enumerate(fk)}
    dts = [
        dur[grid.phase_of_interval[k]] / grid.intervals[grid.phase_of_interval[k]]
        for k in range(n - 1)
    ]

    if cfg.symbolic == "MX":
        f_all = ca.horzcat(
            *[
                f_s[:, force_index[k]] * FORCE_SCALE_N if k in force_index else ca.MX.zeros(NF)
                for k in range(n)
            ]
        )
        dyn_rows, torque_rows, integ_rows, cost, torque_u = _mapped_dynamics(
            model, cfg, grid, r, rd, rdd, w_s, w_mid, f_all, ca.horzcat(*dts), weight_w
        )
    else:
        cost = 0.0
        dyn_rows, torque_rows, integ_rows = [], [], []
        torque_u: list[float] = []
        for k in range(n):
            f_k = f_s[:, force_index[k]] * FORCE_SCALE_N if k in force_index else SYM.zeros(NF)
            tau = model.inverse_dynamics(r[:, k], rd[:, k], rdd[:, k], f_k)
            dyn_rows.append((tau[0:6] - w_s[:, k] * WRENCH_SCALE) / WRENCH_SCALE)
            torque_rows.append(tau[6:] / effort)
            torque_u.append(float(k))
            dt_cost = dts[min(k, n - 2)]
            cost += weight_w * dt_cost * ca.sumsqr(w_s[:, k])
            cost += cfg.torque_weight * dt_cost * ca.sumsqr(tau[6:] / effort)
            cost += cfg.acceleration_weight * dt_cost * ca.sumsqr(rdd[3:, k])
            if k < n - 1:
                h = dts[k]
                integ_rows.append(rd[:, k + 1] - rd[:, k] - h / 2 * (rdd[:, k] + rdd[:, k + 1]))
                integ_rows.append(
                    r[:, k + 1]
                    - r[:, k]
                    - h * rd[:, k]
                    - h**2 / 6 * (2 * rdd[:, k] + rdd[:, k + 1])
                )
                if cfg.midpoint_constraints:
                    # torque limits and dynamics also at the interval midpoint of the interpolant
                    jump = rdd[:, k + 1] - rdd[:, k]
                    rdd_m = rdd[:, k] + jump / 2
                    rd_m = rd[:, k] + h / 2 * rdd[:, k] + h / 8 * jump
                    r_m = r[:, k] + h / 2 * rd[:, k] + h**2 / 8 * rdd[:, k] + h**2 / 48 * jump
                    f_next = (
                        f_s[:, force_index[k + 1]] * FORCE_SCALE_N
                        if k + 1 in force_index
                        else SYM.zeros(NF)
                    )
                    if grid.phase_of_interval[k] == AIR_PHASE:
                        f_m = SYM.zeros(NF)
                    else:
                        f_m = (f_k + f_next) / 2
                    tau_m = model.inverse_dynamics(r_m, rd_m, rdd_m, f_m)
                    torque_rows.append(tau_m[6:] / effort)
                    torque_u.append(k + 0.5)
                    if cfg.quarter_point_torques:
                        air_k = grid.phase_of_interval[k] == AIR_PHASE
                        for frac in (0.25, 0.75):
                            f_q = SYM.zeros(NF) if air_k else (1 - frac) * f_k + frac * f_next
                            tau_q = model.inverse_dynamics(
                                *_interpolant_at(r[:, k], rd[:, k], rdd[:, k], jump, h, frac), f_q
                            )
                            torque_rows.append(tau_q[6:] / effort)
                            torque_u.append(k + frac)
                    # the dynamics hold at the midpoint too, with its own pelvis wrench
                    dyn_rows.append(tau_m[0:6] / WRENCH_SCALE - w_mid[:, k])
                    cost += weight_w * dts[k] * ca.sumsqr(w_mid[:, k])
    add(
        "inverse dynamics (base rows = pelvis wrench, knots and midpoints)",
        ca.vertcat(*dyn_rows),
        0.0,
        0.0,
    )
    # joints the TO does not move get a fraction of their limit, left to the PD that holds them
    moved = np.zeros(len(effort), dtype=bool)
    for cols in model.joint_columns:
        moved[list(cols)] = True
    scale = np.where(moved, alpha, alpha * cfg.held_joint_torque_fraction)
    limit_fraction = scale.copy()
    # the torque between the knot and midpoint samples is not bounded by them: keep a margin
    scale = scale * (1.0 - cfg.torque_limit_margin)
    num_torque_rows = sum(row.shape[0] for row in torque_rows) // len(effort)
    scale_rows = np.tile(scale, num_torque_rows)
    add("torque limits alpha*tau_max", ca.vertcat(*torque_rows), -scale_rows, scale_rows)
    add("integration (trapezoidal, linear acceleration)", ca.vertcat(*integ_rows), 0.0, 0.0)
    if cfg.limits_between_knots:
        pos_rows, speed_rows = _between_knot_limit_rows(r, rd, rdd, dts)
        lower, upper = model.lower_r[3:], model.upper_r[3:]
        add(
            "joint position limits between knots (cubic's Bernstein control points)",
            pos_rows,
            np.tile(lower, 2 * (n - 1)),
            np.tile(upper, 2 * (n - 1)),
        )
        speed = np.tile(model.velocity_limit[3:], n - 1)
        add(
            "joint speed limits between knots (quadratic's Bernstein control point)",
            speed_rows,
            -speed,
            speed,
        )

    # contact: friction pyramid and unilateral normal force at each heel/toe point
    mu = cfg.friction_coefficient
    fx, fz = f_s[0::2, :], f_s[1::2, :]
    add("unilateral contact and friction cone", ca.vertcat(fz - fx / mu, fz + fx / mu), 0.0, np.inf)

    # soles: placed at the start (3 independent coordinates of the rigid sole: heel x, z; toe z),
    # flat on the floor at touch-down, and at rest (zero heel/toe velocity) at every stance knot
    sole_rows = []
    pts0 = model.sole_points(r[:, 0])
    sole_rows.append(
        ca.vertcat(
            pts0[0, 0] - p_stand[0, 0], pts0[2, 0] - p_stand[2, 0], pts0[2, 1] - p_stand[2, 1]
        )
    )
    pts_td = model.sole_points(r[:, grid.touchdown_knot])
    sole_rows.append(ca.vertcat(pts_td[2, 0], pts_td[2, 1]))
    add("sole placement at start and touch-down", ca.vertcat(*sole_rows), 0.0, 0.0)
    vel_rows = []
    for k in grid.fixed_sole_knots():
        vel = model.sole_points_velocity(r[:, k], rd[:, k])
        vel_rows.append(ca.vertcat(vel[0, 0], vel[2, 0], vel[2, 1]))
    add(
        "stance soles at rest (no slip, no energy through contacts)",
        ca.vertcat(*vel_rows),
        0.0,
        0.0,
    )
    # the velocity rows leave a second-order drift of the sole between knots: keep it within a band
    band = cfg.sole_drift_tolerance_m
    drift_rows, drift_lo, drift_hi = [], [], []
    for k in grid.fixed_sole_knots():
        pts = model.sole_points(r[:, k])
        landed = k > grid.takeoff_knot
        ref = model.sole_points(r[:, grid.touchdown_knot]) if landed else p_stand
        ref_z = SYM.zeros(2) if landed else p_stand[2, :]
        drift_rows.append(
            ca.vertcat(pts[0, 0] - ref[0, 0], pts[2, 0] - ref_z[0], pts[2, 1] - ref_z[1])
        )
        drift_lo.append([-band, 0.0, 0.0] if landed else [-band, -band, -band])
        drift_hi.append([band, band, band])
    add(
        "stance sole drift within the band",
        ca.vertcat(*drift_rows),
        np.concatenate(drift_lo),
        np.concatenate(drift_hi),
    )

    air = range(grid.takeoff_knot + 1, grid.touchdown_knot)
    clear = [model.sole_points(r[:, k])[2, :].T for k in air]
    add("no sole penetration in the air", ca.vertcat(*clear), cfg.min_air_sole_height_m, np.inf)
    add("pelvis height", r[1, :].T, cfg.min_pelvis_height_m, np.inf)
    parts = [model.clearance_heights(r[:, k]) for k in range(n)]
    add("hand and knee clearance", ca.vertcat(*parts), cfg.min_limb_height_m, np.inf)
    if cfg.shin_clearance:
        shins = [model.shin_heights(r[:, k]) for k in range(n)]
        add("shin clearance", ca.vertcat(*shins), cfg.min_shin_height_m, np.inf)
    # centre of pressure away from the sole edges: each of heel and toe carries a share
    c = cfg.cop_margin
    total = fz[0, :] + fz[1, :]
    add(
        "centre of pressure inside the sole margin",
        ca.vertcat(fz[0, :] - c * total, fz[1, :] - c * total).T,
        0.0,
        np.inf,
    )

    # boundary conditions: start at the stand pose at rest, land upright after a full turn at rest
    add("start at rest in the stand pose", ca.vertcat(r[:, 0] - stand, rd[:, 0]), 0.0, 0.0)
    final = ca.vertcat(rd[:, n - 1], rdd[:, n - 1], r[2, n - 1] - cfg.turn_rad)
    add("land upright after the full turn, at rest", final, 0.0, 0.0)
    tol = cfg.final_joint_tolerance_rad
    add("landed joints near the stand pose", r[3:, n - 1] - stand[3:], -tol, tol)

    # variable bounds
    inf = np.inf
    lb_r = np.tile(np.where(np.isfinite(model.lower_r), model.lower_r, -inf), (n, 1))
    ub_r = np.tile(np.where(np.isfinite(model.upper_r), model.upper_r, inf), (n, 1))
    lb_r[:, 2], ub_r[:, 2] = min(0.0, cfg.turn_rad) - 1.0, max(0.0, cfg.turn_rad) + 1.0
    lean = cfg.max_stance_lean_rad
    lb_r[: grid.takeoff_knot + 1, 2] = -lean
    ub_r[: grid.takeoff_knot + 1, 2] = lean
    lb_r[grid.touchdown_knot :, 2] = cfg.turn_rad - lean
    ub_r[grid.touchdown_knot :, 2] = cfg.turn_rad + lean
    vel = np.where(np.isfinite(model.velocity_limit), model.velocity_limit, inf)
    lb_rd, ub_rd = np.tile(-vel, (n, 1)), np.tile(vel, (n, 1))
    lb_rdd, ub_rdd = np.full((n, NR), -inf), np.full((n, NR), inf)
    w_hi = np.array([cfg.max_wrench_force_n] * 3 + [cfg.max_wrench_torque_nm] * 3) / WRENCH_SCALE
    if cfg.forbid_wrench:
        w_hi = np.zeros(6)
    lb_w, ub_w = np.tile(-w_hi, (n, 1)), np.tile(w_hi, (n, 1))
    lb_f = np.tile([-inf, 0.0], (len(fk), NF // 2))
    ub_f = np.full((len(fk), NF), inf)
    lb_t = np.array([p.min_duration_s for p in phases])
    ub_t = np.array([p.max_duration_s for p in phases])
    lb_wm, ub_wm = np.tile(-w_hi, (n - 1, 1)), np.tile(w_hi, (n - 1, 1))
    lbx = np.concatenate(
        [
            lb_r.ravel(),
            lb_rd.ravel(),
            lb_rdd.ravel(),
            lb_w.ravel(),
            lb_f.ravel(),
            lb_t,
            lb_wm.ravel(),
        ]
    )
    ubx = np.concatenate(
        [
            ub_r.ravel(),
            ub_rd.ravel(),
            ub_rdd.ravel(),
            ub_w.ravel(),
            ub_f.ravel(),
            ub_t,
            ub_wm.ravel(),
        ]
    )
    return Transcription(
        cfg=cfg,
        grid=grid,
        nlp={"x": x, "f": cost, "g": ca.vertcat(*g_rows), "p": weight_w},
        lbx=lbx,
        ubx=ubx,
        lbg=np.concatenate(lbg),
        ubg=np.concatenate(ubg),
        groups=groups,
        unpack=unpack,
        force_knots=fk,
        num_params=1,
        torque_sample_u=np.asarray(torque_u, dtype=float),
        torque_limit_fraction=limit_fraction,
    )


def _interpolant_at(r0, rd0, rdd0, jump, h, frac):
    """(r, rd, rdd) of the collocation's interpolant at ``frac`` of an interval of length h that
    starts at (r0, rd0, rdd0) with acceleration change ``jump`` over the interval."""
    t = frac * h
    rdd = rdd0 + frac * jump
    rd = rd0 + t * rdd0 + t * frac * jump / 2
    r = r0 + t * rd0 + t**2 * rdd0 / 2 + t**2 * frac * jump / 6
    return r, rd, rdd


def _between_knot_limit_rows(r, rd, rdd, dts) -> tuple:
    """Inner Bernstein control points of the joints' interpolant in every interval.

    On an interval of length h the position is the cubic with Bernstein control points
    (r_k, r_k + h rd_k / 3, r_{k+1} - h rd_{k+1} / 3, r_{k+1}) and the speed the quadratic with
    (rd_k, rd_k + h rdd_k / 2, rd_{k+1}). A Bernstein polynomial stays inside the convex hull of
    its control points, so bounding the inner ones (the knots are bounded as variables) keeps the
    whole interpolant within the limits: a sufficient, smooth condition, linear in the states for a
    given h. Returns (position rows (2 N x 5,), speed rows (N x 5,)), knot-major.
    """
    joints = slice(3, NR)
    pos, vel = [], []
    for k, h in enumerate(dts):
        pos.append(r[joints, k] + h / 3 * rd[joints, k])
        pos.append(r[joints, k + 1] - h / 3 * rd[joints, k + 1])
        vel.append(rd[joints, k] + h / 2 * rdd[joints, k])
    return ca.vertcat(*pos), ca.vertcat(*vel)


def _mapped_dynamics(model, cfg, grid, r, rd, rdd, w_s, w_mid, f_all, h_row, weight_w):
    """Knot and interval rows as two SX functions mapped over the grid (MX graph).

    Each function's derivatives are generated once and mapped, which builds the solver in seconds
    where the fully inlined SX graph of ~140 whole-body RNEAs takes tens of seconds.
    """
    effort = model.effort_limit_nm
    n = grid.num_knots
    rs, rds, rdds = ca.SX.sym("r", NR), ca.SX.sym("rd", NR), ca.SX.sym("rdd", NR)
    fs, ws = ca.SX.sym("f", NF), ca.SX.sym("w", 6)
    tau = model.inverse_dynamics(rs, rds, rdds, fs)
    knot_fn = ca.Function(
        "knot_rows",
        [rs, rds, rdds, fs, ws],
        [
            (tau[0:6] - ws * WRENCH_SCALE) / WRENCH_SCALE,
            tau[6:] / effort,
            ca.sumsqr(tau[6:] / effort),
        ],
    )
    r1, rd1, rdd1 = ca.SX.sym("r1", NR), ca.SX.sym("rd1", NR), ca.SX.sym("rdd1", NR)
    hs, wms = ca.SX.sym("h"), ca.SX.sym("wm", 6)
    jump = rdd1 - rdds
    integ = ca.vertcat(
        rd1 - rds - hs / 2 * (rdds + rdd1),
        r1 - rs - hs * rds - hs**2 / 6 * (2 * rdds + rdd1),
    )
    rdd_m = rdds + jump / 2
    rd_m = rds + hs / 2 * rdds + hs / 8 * jump
    r_m = rs + hs / 2 * rds + hs**2 / 8 * rdds + hs**2 / 48 * jump
    tau_m = model.inverse_dynamics(r_m, rd_m, rdd_m, fs)
    f0, f1 = ca.SX.sym("f0", NF), ca.SX.sym("f1", NF)
    quarter = [
        model.inverse_dynamics(
            *_interpolant_at(rs, rds, rdds, jump, hs, frac), (1 - frac) * f0 + frac * f1
        )[6:]
        / effort
        for frac in (0.25, 0.75)
    ]
    interval_fn = ca.Function(
        "interval_rows",
        [rs, rds, rdds, r1, rd1, rdd1, fs, hs, wms, f0, f1],
        [integ, tau_m[0:6] / WRENCH_SCALE - wms, tau_m[6:] / effort, ca.vertcat(*quarter)],
    )
    dyn_k, torque_k, tcost_k = knot_fn.map(n)(r, rd, rdd, f_all, w_s)
    air = np.array([grid.phase_of_interval[k] == AIR_PHASE for k in range(n - 1)], dtype=float)
    f_mid = (f_all[:, :-1] + f_all[:, 1:]) / 2 * ca.repmat(ca.DM(1.0 - air).T, NF, 1)
    stance = ca.repmat(ca.DM(1.0 - air).T, NF, 1)
    integ_i, dyn_m, torque_m, torque_q = interval_fn.map(n - 1)(
        r[:, :-1], rd[:, :-1], rdd[:, :-1], r[:, 1:], rd[:, 1:], rdd[:, 1:], f_mid, h_row, w_mid,
        f_all[:, :-1] * stance, f_all[:, 1:] * stance,
    )  # fmt: skip
    h_knot = ca.horzcat(h_row, h_row[:, -1])
    cost = weight_w * ca.dot(h_knot, ca.sum1(w_s**2))
    cost += cfg.torque_weight * ca.dot(h_knot, tcost_k)
    cost += cfg.acceleration_weight * ca.dot(h_knot, ca.sum1(rdd[3:, :] ** 2))
    dyn_rows, torque_rows = [ca.vec(dyn_k)], [ca.vec(torque_k)]
    torque_u = [float(k) for k in range(n)]
    if cfg.midpoint_constraints:
        dyn_rows.append(ca.vec(dyn_m))
        torque_rows.append(ca.vec(torque_m))
        torque_u += [k + 0.5 for k in range(n - 1)]
        if cfg.quarter_point_torques:
            torque_rows.append(ca.vec(torque_q))
            torque_u += [k + frac for k in range(n - 1) for frac in (0.25, 0.75)]
        cost += weight_w * ca.dot(h_row, ca.sum1(w_mid**2))
    return dyn_rows, torque_rows, [ca.vec(integ_i)], cost, torque_u


# ---------------------------------------------------------------- initial guess

# key poses of the moved joints (hip, knee, ankle, shoulder, elbow pitch) [rad]
_CROUCH = np.array([-1.2, 2.0, -0.8, 0.8, 0.3])
_TAKEOFF = np.array([-0.1, 0.1, 0.3, -2.5, 0.2])
_TUCK = np.array([-2.2, 2.5, -0.3, -1.0, 1.2])
_LAND = np.array([-0.9, 1.6, -0.7, 0.5, 0.6])


def _stance_base_solver(model: SagittalModel, target: np.ndarray):
    """Newton solver: joints (6,) -> base (x, z, pitch) putting the left sole on ``target``."""
    base = ca.SX.sym("base", 3)
    joints = ca.SX.sym("joints", NR - 3)
    pts = model.sole_points(ca.vertcat(base, joints))
    res = ca.vertcat(pts[0, 0] - target[0, 0], pts[2, 0] - target[2, 0], pts[2, 1] - target[2, 1])
    fn = ca.Function("stance_residual", [base, joints], [res, ca.jacobian(res, base)])

    def solve(joint_pos: np.ndarray) -> np.ndarray:
        b = np.array([0.0, 0.7, 0.0])
        for _ in range(30):
            res_b, jac_b = fn(b, joint_pos)
            step = np.linalg.solve(np.asarray(jac_b), np.asarray(res_b).ravel())
            b = b - step
            if np.abs(step).max() < 1e-12:
                break
        return b

    return solve


def _blend(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    s = 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0.0, 1.0))
    return a[None, :] + s[:, None] * (b - a)[None, :]


def initial_guess(model: SagittalModel, cfg: BackflipConfig) -> Solution:
    """A hand-designed kinematic flip: crouch, extend, tuck and turn -2 pi on a ballistic arc, land.

    Stance knots are placed with the soles exactly on the ground; velocities and accelerations are
    the finite differences of the semi-implicit scheme; forces carry the weight; w is what the
    guess's inverse dynamics leaves on the base rows (clipped to its bounds).
    """
    grid = make_grid(cfg)
    phases = cfg.phases()
    durations = np.array([p.guess_duration_s for p in phases])
    n = grid.num_knots
    stand = model.r_stand()
    p_stand = np.asarray(model.sole_points(stand))
    counts = grid.intervals
    starts = np.concatenate([[0], np.cumsum(counts)])
    joints = np.zeros((n, NR - 3))
    s = lambda i: np.linspace(0.0, 1.0, counts[i] + 1)  # noqa: E731
    j_stand = stand[3:]
    joints[starts[0] : starts[1] + 1] = j_stand
    joints[starts[1] : starts[2] + 1] = _blend(j_stand, _CROUCH, s(1))
    joints[starts[2] : starts[3] + 1] = _blend(_CROUCH, _TAKEOFF, s(2))
    air = s(3)
    first = air <= 0.4
    joints[starts[3] : starts[4] + 1][first] = _blend(_TAKEOFF, _TUCK, air[first] / 0.4)
    joints[starts[3] : starts[4] + 1][~first] = _blend(_TUCK, _LAND, (air[~first] - 0.4) / 0.6)
    joints[starts[4] : starts[5] + 1] = _blend(_LAND, j_stand, s(4))
    r = np.zeros((n, NR))
    r[:, 3:] = joints
    place_base = _stance_base_solver(model, p_stand)
    for k in grid.fixed_sole_knots():
        r[k, :3] = place_base(joints[k])
        if k > grid.takeoff_knot:
            r[k, 2] += cfg.turn_rad  # landed after the turn
    # ballistic base arc through the air, pitch turning uniformly
    k0, k1 = grid.takeoff_knot, grid.touchdown_knot
    t_air = durations[3]
    tt = np.linspace(0.0, t_air, k1 - k0 + 1)
    z0, z1 = r[k0, 1], r[k1, 1]
    vz0 = (z1 - z0) / t_air + 0.5 * 9.81 * t_air
    r[k0 : k1 + 1, 1] = z0 + vz0 * tt - 0.5 * 9.81 * tt**2
    r[k0 : k1 + 1, 0] = np.linspace(r[k0, 0], r[k1, 0], k1 - k0 + 1)
    r[k0 : k1 + 1, 2] = np.linspace(r[k0, 2], r[k1, 2], k1 - k0 + 1)
    r[k0 : k1 + 1, 3:] = joints[k0 : k1 + 1]
    dt = (durations / np.asarray(counts))[grid.phase_of_interval]
    rd = np.zeros((n, NR))
    rd[1:] = np.diff(r, axis=0) / dt[:, None]
    rdd = np.zeros((n, NR))
    rdd[:-1] = np.diff(rd, axis=0) / dt[:, None]
    force = np.zeros((n, NF))
    weight_n = model.dyn.total_mass_kg * 9.81
    force[grid.force_knots(), 1::2] = weight_n / 4.0
    tau = np.asarray(model.inverse_dynamics.map(n)(r.T, rd.T, rdd.T, force.T)).T
    w_hi = np.array([cfg.max_wrench_force_n] * 3 + [cfg.max_wrench_torque_nm] * 3)
    wrench = np.clip(tau[:, :6], -w_hi, w_hi)
    return Solution(r, rd, rdd, wrench, force, durations, (wrench[:-1] + wrench[1:]) / 2)
