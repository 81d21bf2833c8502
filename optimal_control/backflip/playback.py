"""Physics check: play a solved backflip back in MuJoCo and see whether the G1 really flips.

Control at every physics step (dt 0.005 s): the G1's own position actuators track the solved joint
trajectory with feed-forward torques, ``tau = tau_ff + Kp (q_ref - q) + Kd (qd_ref - qd)``,
saturated at the effort limits (the actuator ``forcerange``); it is written as a position target
``ctrl = q_ref + (tau_ff + Kd qd_ref) / Kp``. The TO's pelvis wrench, converted to world force and
torque at the pelvis CoM, is applied as ``xfrc_applied`` (or switched off). The base is not
controlled: it flips (or not) from the contact forces the legs produce in MuJoCo's soft contact
model, which differs from the TO's rigid contact, so this is an honest open-loop test.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from optimal_control.backflip.config import AIR_PHASE
from optimal_control.backflip.trajectory import SampledFlip
from optimal_control.wrench_qp import xfrc_applied_from_pelvis_wrench
from robots import g1
from robots.conventions import pin_to_mj_qpos, pin_to_mj_qvel
from robots.mujoco_model import build_mujoco_model
from robots.standing import with_scaled_gains


@dataclass(frozen=True)
class PlaybackConfig:
    """Options of the MuJoCo playback."""

    # multipliers of the G1 table PD gains Kp, Kd, one playback each (with and without w); the
    # table gains cannot hold even the standing robot open loop (robots/standing.py)
    gain_scales: tuple[float, ...] = (1.0, 3.0)
    settle_s: float = 1.0  # time simulated after the reference ends, holding the last pose [s]
    upright_cos: float = 0.9  # landed upright: pelvis z axis . world z at least this [-]
    min_pelvis_height_m: float = 0.55  # landed standing: pelvis at least this high [m]
    pitch_tol_rad: float = 0.5  # completed: total pitch within this of the turn [rad]


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

    def to_dict(self) -> dict:
        """JSON-ready."""
        return {
            k: (
                bool(v)
                if isinstance(v, bool | np.bool_)
                else float(v)
                if k != "with_wrench"
                else bool(v)
            )
            for k, v in asdict(self).items()
        }


def _pitch(rot: np.ndarray) -> float:
    """Rotation angle about world y of a (nearly) sagittal rotation matrix."""
    return float(np.arctan2(rot[0, 2], rot[2, 2]))


def play_back(
    flip: SampledFlip,
    with_wrench: bool,
    cfg: PlaybackConfig = PlaybackConfig(),
    turn_rad: float = -2 * np.pi,
    gain_scale: float = 1.0,
) -> tuple[PlaybackResult, np.ndarray]:
    """Simulate ``flip`` (sampled at the MuJoCo step) in MuJoCo.

    Returns the result and the simulated qpos trajectory (T_sim, 36) (for a video).
    """
    model = build_mujoco_model()
    if abs(flip.dt_s - model.opt.timestep) > 1e-9:
        raise ValueError(
            f"Sample the flip at the MuJoCo step ({model.opt.timestep} s), got {flip.dt_s} s."
        )
    model = with_scaled_gains(model, gain_scale)
    data = mujoco.MjData(model)
    kp = model.actuator_gainprm[:, 0].copy()
    kd = -model.actuator_biasprm[:, 2].copy()
    pelvis = model.body(g1.BASE_LINK).id
    data.qpos[:] = pin_to_mj_qpos(flip.q[0])
    data.qvel[:] = pin_to_mj_qvel(flip.q[0], flip.v[0])
    mujoco.mj_forward(model, data)
    jq = np.arange(7, 7 + g1.NUM_JOINTS)
    jv = np.arange(6, 6 + g1.NUM_JOINTS)
    n = len(flip.time_s)
    settle = int(round(cfg.settle_s / flip.dt_s))
    pitch_prev, turn = 0.0, 0.0
    pitch_err, z_err, joint_err2, saturated = [], [], [], 0
    qpos_log = np.zeros((n + settle, model.nq))
    effort = g1.EFFORT_LIMIT_NM
    touchdown = int(np.flatnonzero(flip.phase == AIR_PHASE)[-1]) + 1
    at_td = (np.nan, np.nan)
    at_end = (np.nan, np.nan)
    for t in range(n + settle):
        i = min(t, n - 1)
        q_ref = flip.q[i, 7:]
        qd_ref = flip.v[i, 6:] if t < n else np.zeros(g1.NUM_JOINTS)
        tau_ff = flip.tau_nm[i]
        data.ctrl[:] = q_ref + (tau_ff + kd * qd_ref) / kp
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
        if t < n:
            ref_pitch = flip.r[min(t + 1, n - 1), 2]
            pitch_err.append(abs(turn - ref_pitch))
            z_err.append(abs(data.qpos[2] - flip.q[min(t + 1, n - 1), 2]))
            joint_err2.append(np.mean((data.qpos[jq] - flip.q[min(t + 1, n - 1), 7:]) ** 2))
            if t + 1 == touchdown:
                at_td = (pitch_err[-1], z_err[-1])
            if t == n - 1:
                at_end = (turn, float(data.xpos[pelvis][2]))
    del jv
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
    )
    return result, qpos_log
