"""Physics check: play a solved backflip back in MuJoCo and see whether the G1 really flips.

Control at every physics step (dt 0.005 s): the G1's own position actuators track the solved joint
trajectory with feed-forward torques, ``tau = tau_ff + Kp (q_ref - q) + Kd (qd_ref - qd)``,
saturated at the effort limits (the actuator ``forcerange``); it is written as a position target
``ctrl = q_ref + (tau_ff + Kd qd_ref) / Kp``. The TO's pelvis wrench, converted to world force and
torque at the pelvis CoM, is applied as ``xfrc_applied`` (or switched off). The base is not
controlled: it flips (or not) from the contact forces the legs produce in MuJoCo's soft contact
model, which differs from the TO's rigid contact, so this is an honest open-loop test. The playback
model's contacts are made as stiff as MuJoCo allows at its step (``contact_timeconst_s``, the TO's
contact is rigid); nothing acts on the base but gravity, contacts and (optionally) the TO's wrench.

:func:`play_flight` isolates the flight: it starts MuJoCo in the reference's take-off state with
contacts off and plays the Air phase only, so it checks the flight modelling (inertias, armature,
torque timing, wrench convention) apart from the push-off.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import mujoco
import numpy as np
import pinocchio as pin

from optimal_control.backflip.config import AIR_PHASE
from optimal_control.backflip.trajectory import SampledFlip
from optimal_control.validation import require_finite_fields
from optimal_control.wrench_qp import xfrc_applied_from_pelvis_wrench
from robots import g1
from robots.conventions import (
    pin_to_mj_qpos,
    pin_to_mj_qvel,
    quat_wxyz_to_matrix,
    quat_xyzw_to_wxyz,
)
from robots.mujoco_model import build_mujoco_model
from robots.pinocchio_model import build_pinocchio_model
from robots.standing import with_scaled_gains


@dataclass(frozen=True)
class PlaybackConfig:
    """Options of the MuJoCo playback."""

    gain_scales: tuple[float, ...] = (1.0, 3.0)  # G1 table PD gain multipliers, one run each [-]
    settle_s: float = 1.0  # time simulated after the reference, in its end pose [s]
    upright_cos: float = 0.9  # landed upright: pelvis z axis . world z at least this [-]
    min_pelvis_height_m: float = 0.55  # landed standing: pelvis at least this high [m]
    pitch_tol_rad: float = 0.5  # completed: total pitch within this of the turn [rad]
    contact_timeconst_s: float = 0.01  # time constant (solref[0]) of every contact [s]

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field and its flag."""
        require_finite_fields(self)

    def validate(self, timestep_s: float) -> None:
        """Raise ValueError naming a bad field."""
        if self.contact_timeconst_s < 2 * timestep_s - 1e-12:
            raise ValueError(
                f"contact_timeconst_s must be >= 2 MuJoCo steps ({2 * timestep_s} s), got "
                f"{self.contact_timeconst_s} s; MuJoCo would clamp it."
            )


@dataclass
class PlaybackResult:
    """Outcome of one playback."""

    with_wrench: bool  # the TO pelvis wrench was applied
    gain_scale: float  # multiplier of the table PD gains used
    completed_flip: bool  # turned the full turn (within tolerance), landed upright, standing
    final_pitch_rad: float  # accumulated pelvis pitch at the end (after settling) [rad]
    pitch_at_reference_end_rad: float  # accumulated pelvis pitch when the reference ends [rad]
    height_at_reference_end_m: float  # pelvis height when the reference ends [m]
    final_pelvis_height_m: float  # [m]
    final_upright_cos: float  # pelvis z axis . world z at the end [-]
    max_pitch_error_rad: float  # max |pitch - pitch_ref| along the reference [rad]
    max_height_error_m: float  # max |z - z_ref| of the pelvis along the reference [m]
    pitch_error_at_touchdown_rad: float  # [rad]
    height_error_at_touchdown_m: float  # [m]
    rms_joint_error_rad: float  # RMS joint tracking error along the reference [rad]
    saturated_fraction: float  # fraction of actuator-steps at the effort limit [-]
    # centroidal angular momentum about world y at take-off (first Air sample) [N m s]
    takeoff_ang_momentum_y_nms: float
    ref_takeoff_ang_momentum_y_nms: float  # the same for the reference [N m s]
    takeoff_com_velocity_xz_mps: tuple  # CoM velocity (x, z) at take-off [m/s]
    ref_takeoff_com_velocity_xz_mps: tuple  # the same for the reference [m/s]
    max_waist_pitch_error_before_takeoff_rad: float  # held waist pitch vs reference [rad]
    waist_pitch_saturated_before_takeoff_s: float  # time the waist pitch is at its limit [s]

    def to_dict(self) -> dict:
        """JSON-ready."""
        out = {}
        for k, v in asdict(self).items():
            if isinstance(v, bool | np.bool_):
                out[k] = bool(v)
            elif isinstance(v, tuple | list):
                out[k] = [float(x) for x in v]
            else:
                out[k] = float(v)
        return out


def _pitch(rot: np.ndarray) -> float:
    """Rotation angle about world y of a (nearly) sagittal rotation matrix."""
    return float(np.arctan2(rot[0, 2], rot[2, 2]))


def reference_centroidal(flip: SampledFlip) -> tuple[np.ndarray, np.ndarray]:
    """Reference centroidal angular momentum about world y (T,) [N m s] and CoM velocity (T, 3)
    [m/s] (Pinocchio, from ``flip.q``, ``flip.v``)."""
    robot = build_pinocchio_model()
    data = robot.model.createData()
    mass = pin.computeTotalMass(robot.model)
    ang = np.zeros(len(flip.time_s))
    vel = np.zeros((len(flip.time_s), 3))
    for i, (q, v) in enumerate(zip(flip.q, flip.v, strict=True)):
        pin.computeCentroidalMomentum(robot.model, data, q, v)
        ang[i] = data.hg.angular[1]
        vel[i] = data.hg.linear / mass
    return ang, vel


def _playback_model(cfg: PlaybackConfig, gain_scale: float) -> mujoco.MjModel:
    """The G1 model with scaled PD gains and the playback's contact stiffness."""
    model = with_scaled_gains(build_mujoco_model(), gain_scale)
    cfg.validate(model.opt.timestep)
    model.geom_solref[:, 0] = cfg.contact_timeconst_s
    return model


def _pd_ff_ctrl(flip: SampledFlip, i: int, kp: np.ndarray, kd: np.ndarray, moving: bool):
    """Position target that makes the actuator apply ``tau_ff + Kp (q_ref - q) + Kd (qd_ref - qd)``."""
    qd_ref = flip.v[i, 6:] if moving else np.zeros(g1.NUM_JOINTS)
    return flip.q[i, 7:] + (flip.tau_nm[i] + kd * qd_ref) / kp


def air_inverse_dynamics_gap_nm(flip: SampledFlip) -> np.ndarray:
    """Per Air sample, the largest |MuJoCo inverse-dynamics joint torque - TO torque| [N m].

    MuJoCo's ``mj_inverse`` (contacts off, the TO wrench applied at the pelvis CoM) on the sampled
    reference state and acceleration: zero where the two models and the frame, armature and wrench
    conventions agree. A sample whose joint lies past a URDF limit (the collocation bounds the knots
    only) shows MuJoCo's joint-limit force there.
    """
    model = copy.deepcopy(build_mujoco_model())
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    data = mujoco.MjData(model)
    pelvis = model.body(g1.BASE_LINK).id
    air = np.flatnonzero(flip.phase == AIR_PHASE)
    gap = np.zeros(len(air))
    for n_air, i in enumerate(air):
        q, v, a = flip.q[i], flip.v[i], flip.a[i]
        data.qpos[:] = pin_to_mj_qpos(q)
        data.qvel[:] = pin_to_mj_qvel(q, v)
        rot = quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q[3:7]))
        qacc = a.copy()
        # MuJoCo's base linear velocity is R v_b (world): d/dt = R (a_b + omega_b x v_b)
        qacc[:3] = rot @ (a[:3] + np.cross(v[3:6], v[:3]))
        data.qacc[:] = qacc
        mujoco.mj_inverse(model, data)
        qfrc_w = np.zeros(model.nv)
        wrench = xfrc_applied_from_pelvis_wrench(flip.wrench_w[i])
        mujoco.mj_applyFT(model, data, wrench[:3], wrench[3:], data.xipos[pelvis], pelvis, qfrc_w)
        gap[n_air] = np.max(np.abs(data.qfrc_inverse[6:] - qfrc_w[6:] - flip.tau_nm[i]))
    return gap


@dataclass
class FlightResult:
    """Outcome of :func:`play_flight` (Air phase only, from the reference take-off state)."""

    with_wrench: bool  # the TO pelvis wrench was applied
    gain_scale: float  # multiplier of the table PD gains used
    pitch_error_at_touchdown_rad: float  # MuJoCo - reference pelvis pitch [rad]
    max_pitch_error_rad: float  # over the flight [rad]
    height_error_at_touchdown_m: float  # MuJoCo - reference pelvis height [m]
    max_joint_error_rad: float  # over the flight [rad]

    def to_dict(self) -> dict:
        """JSON-ready."""
        return {k: (v if isinstance(v, bool) else float(v)) for k, v in asdict(self).items()}


def play_flight(
    flip: SampledFlip, with_wrench: bool, cfg: PlaybackConfig = PlaybackConfig(), gain_scale=1.0
) -> FlightResult:
    """Play the Air phase alone: MuJoCo starts in the reference state at take-off, contacts are
    off, the joints get the same PD + feed-forward control as in :func:`play_back`.

    Separates flight modelling errors from the push-off: if this follows the reference, a failed
    full playback lost its rotation on the ground.
    """
    model = _playback_model(cfg, gain_scale)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    air = np.flatnonzero(flip.phase == AIR_PHASE)
    if len(air) < 2:
        raise ValueError("The flip has no Air phase to play (fewer than 2 Air samples).")
    start, touchdown = int(air[0]), int(air[-1]) + 1
    data = mujoco.MjData(model)
    kp = model.actuator_gainprm[:, 0].copy()
    kd = -model.actuator_biasprm[:, 2].copy()
    pelvis = model.body(g1.BASE_LINK).id
    data.qpos[:] = pin_to_mj_qpos(flip.q[start])
    data.qvel[:] = pin_to_mj_qvel(flip.q[start], flip.v[start])
    mujoco.mj_forward(model, data)
    turn = float(flip.r[start, 2])
    pitch_prev = _pitch(data.xmat[pelvis].reshape(3, 3))
    pitch_err, joint_err = [], []
    for t in range(start, touchdown):
        data.ctrl[:] = _pd_ff_ctrl(flip, t, kp, kd, True)
        data.xfrc_applied[pelvis] = (
            xfrc_applied_from_pelvis_wrench(flip.wrench_w[t]) if with_wrench else 0.0
        )
        mujoco.mj_step(model, data)
        p = _pitch(data.xmat[pelvis].reshape(3, 3))
        turn += (p - pitch_prev + np.pi) % (2 * np.pi) - np.pi
        pitch_prev = p
        pitch_err.append(turn - flip.r[t + 1, 2])
        joint_err.append(np.max(np.abs(data.qpos[7:] - flip.q[t + 1, 7:])))
    return FlightResult(
        with_wrench=with_wrench,
        gain_scale=float(gain_scale),
        pitch_error_at_touchdown_rad=float(pitch_err[-1]),
        max_pitch_error_rad=float(np.max(np.abs(pitch_err))),
        height_error_at_touchdown_m=float(data.qpos[2] - flip.q[touchdown, 2]),
        max_joint_error_rad=float(np.max(joint_err)),
    )


def play_back(
    flip: SampledFlip,
    with_wrench: bool,
    cfg: PlaybackConfig = PlaybackConfig(),
    turn_rad: float = -2 * np.pi,
    gain_scale: float = 1.0,
    log: dict | None = None,
) -> tuple[PlaybackResult, np.ndarray]:
    """Simulate ``flip`` (sampled at the MuJoCo step) in MuJoCo.

    Returns the result and the simulated qpos trajectory (T_sim, 36) (for a video). If ``log`` is
    a dict, it receives per-step arrays (T_sim,): ``ang_momentum_y_nms`` (centroidal angular
    momentum about world y) and ``waist_pitch_error_rad`` (MuJoCo - reference).
    """
    model = build_mujoco_model()
    if abs(flip.dt_s - model.opt.timestep) > 1e-9:
        raise ValueError(
            f"Sample the flip at the MuJoCo step ({model.opt.timestep} s), got {flip.dt_s} s."
        )
    model = _playback_model(cfg, gain_scale)
    data = mujoco.MjData(model)
    kp = model.actuator_gainprm[:, 0].copy()
    kd = -model.actuator_biasprm[:, 2].copy()
    pelvis = model.body(g1.BASE_LINK).id
    data.qpos[:] = pin_to_mj_qpos(flip.q[0])
    data.qvel[:] = pin_to_mj_qvel(flip.q[0], flip.v[0])
    mujoco.mj_forward(model, data)
    jq = np.arange(7, 7 + g1.NUM_JOINTS)
    n = len(flip.time_s)
    settle = int(round(cfg.settle_s / flip.dt_s))
    pitch_prev, turn = 0.0, 0.0
    pitch_err, z_err, joint_err2, saturated = [], [], [], 0
    qpos_log = np.zeros((n + settle, model.nq))
    effort = g1.EFFORT_LIMIT_NM
    touchdown = int(np.flatnonzero(flip.phase == AIR_PHASE)[-1]) + 1
    takeoff = int(np.flatnonzero(flip.phase == AIR_PHASE)[0])
    ang_ref, vel_ref = reference_centroidal(flip)
    waist = g1.JOINT_NAMES.index("waist_pitch_joint")
    waist_err, waist_sat_steps = 0.0, 0
    at_td = (np.nan, np.nan)
    at_end = (np.nan, np.nan)
    at_takeoff = (np.nan, (np.nan, np.nan))
    ang_log = np.zeros(n + settle)
    waist_log = np.zeros(n + settle)
    for t in range(n + settle):
        i = min(t, n - 1)
        data.ctrl[:] = _pd_ff_ctrl(flip, i, kp, kd, t < n)
        data.xfrc_applied[pelvis] = (
            xfrc_applied_from_pelvis_wrench(flip.wrench_w[i]) if with_wrench else 0.0
        )
        mujoco.mj_step(model, data)
        rot = data.xmat[pelvis].reshape(3, 3)
        p = _pitch(rot)
        turn += (p - pitch_prev + np.pi) % (2 * np.pi) - np.pi
        pitch_prev = p
        qpos_log[t] = data.qpos
        tau_act = data.actuator_force
        saturated += int(np.sum(np.abs(tau_act) >= effort * (1 - 1e-6)))
        if log is not None:
            mujoco.mj_subtreeVel(model, data)
            ang_log[t] = data.subtree_angmom[pelvis][1]
            waist_log[t] = data.qpos[7 + waist] - flip.q[min(t + 1, n - 1), 7 + waist]
        if t + 1 <= takeoff:
            waist_err = max(waist_err, abs(data.qpos[7 + waist] - flip.q[t + 1, 7 + waist]))
            waist_sat_steps += int(abs(tau_act[waist]) >= effort[waist] * (1 - 1e-6))
        if t + 1 == takeoff:
            mujoco.mj_subtreeVel(model, data)
            at_takeoff = (
                float(data.subtree_angmom[pelvis][1]),
                (float(data.subtree_linvel[pelvis][0]), float(data.subtree_linvel[pelvis][2])),
            )
        if t < n:
            ref_pitch = flip.r[min(t + 1, n - 1), 2]
            pitch_err.append(abs(turn - ref_pitch))
            z_err.append(abs(data.qpos[2] - flip.q[min(t + 1, n - 1), 2]))
            joint_err2.append(np.mean((data.qpos[jq] - flip.q[min(t + 1, n - 1), 7:]) ** 2))
            if t + 1 == touchdown:
                at_td = (pitch_err[-1], z_err[-1])
            if t == n - 1:
                at_end = (turn, float(data.xpos[pelvis][2]))
    if log is not None:
        log["ang_momentum_y_nms"] = ang_log
        log["waist_pitch_error_rad"] = waist_log
    rot = data.xmat[pelvis].reshape(3, 3)
    upright = float(rot[2, 2])
    height = float(data.xpos[pelvis][2])
    completed = (
        abs(turn - turn_rad) <= cfg.pitch_tol_rad
        and upright >= cfg.upright_cos
        and height >= cfg.min_pelvis_height_m
    )
    result = PlaybackResult(
        with_wrench=with_wrench,
        gain_scale=float(gain_scale),
        completed_flip=bool(completed),
        final_pitch_rad=float(turn),
        pitch_at_reference_end_rad=float(at_end[0]),
        height_at_reference_end_m=float(at_end[1]),
        final_pelvis_height_m=height,
        final_upright_cos=upright,
        max_pitch_error_rad=float(np.max(pitch_err)),
        max_height_error_m=float(np.max(z_err)),
        pitch_error_at_touchdown_rad=float(at_td[0]),
        height_error_at_touchdown_m=float(at_td[1]),
        rms_joint_error_rad=float(np.sqrt(np.mean(joint_err2))),
        saturated_fraction=saturated / ((n + settle) * g1.NUM_JOINTS),
        takeoff_ang_momentum_y_nms=at_takeoff[0],
        ref_takeoff_ang_momentum_y_nms=float(ang_ref[takeoff]),
        takeoff_com_velocity_xz_mps=at_takeoff[1],
        ref_takeoff_com_velocity_xz_mps=(float(vel_ref[takeoff, 0]), float(vel_ref[takeoff, 2])),
        max_waist_pitch_error_before_takeoff_rad=float(waist_err),
        waist_pitch_saturated_before_takeoff_s=waist_sat_steps * flip.dt_s,
    )
    return result, qpos_log
