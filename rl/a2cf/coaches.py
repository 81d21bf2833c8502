"""Model-based coaches: state-dependent pelvis wrenches the force agent is distilled from.

A coach maps the batch :class:`EnvState` to a pelvis wrench (N, 6) [N, Nm] in the assist action's
heading frame (:class:`rl.envs.assist_action.AssistAction`), bounded by the env's current eta.
It assists *as needed*: inside a tolerance band around the reference the learner is on its own
(zero wrench), beyond it the help grows linearly with the excess: a coach that does all the
balancing leaves the learner nothing to learn (docs/training.md). Reference-tracking coaches for
walk, dance and backflip come from the oracle artifacts (``optimal_control.coach``);
:class:`PostureCoach` is the built-in one for balance tasks without a time-indexed reference
(stand).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from rl.envs.state import EnvState, quat_rotate, world_to_heading
from rl.envs.vec_env import GRAVITY_MPS2, G1VecEnv


@dataclass(frozen=True)
class PostureCoachConfig:
    """Gains (from the robot's mass and inertia) and tolerance band of the posture coach."""

    natural_frequency_hz: float = 1.5  # closed-loop frequency the PD gains are sized for [Hz]
    damping_ratio: float = 1.0  # critical damping [-]
    tilt_band_rad: float = 0.15  # no help while the pelvis tilts less than this [rad]
    height_band_m: float = 0.08  # no help while the pelvis is within this of its height [m]
    height_ref_m: float = 0.74  # reference pelvis height (the stand task's target) [m]

    def __post_init__(self) -> None:
        if self.natural_frequency_hz <= 0 or self.damping_ratio < 0:
            raise ValueError("posture coach needs a positive frequency and a damping ratio >= 0")
        if self.tilt_band_rad < 0 or self.height_band_m < 0:
            raise ValueError("posture coach tolerance bands must be >= 0")


class PostureCoach:
    """PD on pelvis tilt and height beyond a tolerance band, gains from the G1's mass and inertia.

    Height: ``f_z = m w^2 e_h - 2 zeta m w v_z`` with ``e_h`` the height error beyond the band.
    Tilt (an inverted pendulum pivoting on the ankles, CoM height ``h``): the torque about the
    horizontal tilt axis is ``(I w^2 + m g h) e_t - 2 zeta I w omega_xy`` with ``I = m h^2`` and
    ``e_t`` the tilt beyond the band; the ``m g h`` term cancels gravity's toppling stiffness.
    Damping only acts outside the band (inside, the learner is on its own).
    """

    def __init__(self, cfg: PostureCoachConfig, mass_kg: float, com_height_m: float) -> None:
        self.cfg = cfg
        w = 2 * math.pi * cfg.natural_frequency_hz
        inertia = mass_kg * com_height_m**2
        self.kp_height = mass_kg * w**2  # [N/m]
        self.kd_height = 2 * cfg.damping_ratio * mass_kg * w  # [N s/m]
        self.kp_tilt = inertia * w**2 + mass_kg * GRAVITY_MPS2 * com_height_m  # [Nm/rad]
        self.kd_tilt = 2 * cfg.damping_ratio * inertia * w  # [Nm s/rad]

    @classmethod
    def for_env(cls, env: G1VecEnv, cfg: PostureCoachConfig = PostureCoachConfig()) -> PostureCoach:
        """Sized from the env's nominal model: total mass and standing CoM height."""
        data = mujoco.MjData(env.model)
        mujoco.mj_setState(
            env.model, data, env.layout.stand_state, mujoco.mjtState.mjSTATE_FULLPHYSICS
        )
        mujoco.mj_forward(env.model, data)
        return cls(cfg, env.total_mass_kg, float(data.subtree_com[0, 2]))

    def __call__(self, s: EnvState) -> torch.Tensor:
        """Heading-frame wrench (N, 6) [N, Nm] (the frame of the assist action), clipped to the
        env's bound of each env's phase."""
        n = s.base_pos_w.shape[0]
        wrench = torch.zeros(n, 6)
        h_err = self.cfg.height_ref_m - s.base_pos_w[:, 2]
        excess_h = torch.sign(h_err) * (h_err.abs() - self.cfg.height_band_m).clamp_min(0)
        outside_h = excess_h != 0
        wrench[:, 2] = (
            self.kp_height * excess_h - self.kd_height * s.base_lin_vel_w[:, 2] * outside_h
        )
        z_body_w = quat_rotate(s.base_quat_w, torch.tensor([0.0, 0.0, 1.0]).expand(n, 3))
        axis = torch.cross(z_body_w, torch.tensor([0.0, 0.0, 1.0]).expand(n, 3), dim=-1)
        sin_tilt = axis.norm(dim=-1)
        tilt = torch.atan2(sin_tilt, z_body_w[:, 2])
        excess_t = (tilt - self.cfg.tilt_band_rad).clamp_min(0)
        unit = axis / sin_tilt.clamp_min(1e-9).unsqueeze(-1)
        omega_w = quat_rotate(s.base_quat_w, s.base_ang_vel_b)
        outside_t = (excess_t > 0).unsqueeze(-1)
        torque = self.kp_tilt * excess_t.unsqueeze(-1) * unit - self.kd_tilt * omega_w * outside_t
        wrench[:, 3:5] = torque[:, :2]
        wrench = world_to_heading(wrench, s.base_quat_w)  # the assist wrench's frame
        bound = s.assist_bound
        return torch.maximum(torch.minimum(wrench, bound), -bound)


@dataclass(frozen=True)
class ArtifactCoachConfig:
    """Tolerance band of the reference-tracking coach used for the warm start (assist as needed)."""

    band_position_m: float = 0.05  # no help while the pelvis is within this of the reference [m]
    band_orientation_rad: float = 0.15  # ... and within this of its orientation [rad]


class ArtifactCoach:
    """The oracle artifact's coach (:mod:`optimal_control.coach`: feed-forward from the per-frame
    wrench QP plus PD on the pelvis pose, gains from the robot's mass and inertia), evaluated on
    the env's state at each env's time along the reference, in the assist wrench's heading frame
    and clipped to the env's bound."""

    def __init__(self, folder: str, cfg: ArtifactCoachConfig = ArtifactCoachConfig()) -> None:
        from optimal_control.artifact import OracleArtifact
        from optimal_control.coach import CoachConfig, coach_from_artifact

        self.artifact = OracleArtifact.load(folder)
        self._anchors: dict[str | None, float] = {}
        self.coach = coach_from_artifact(
            self.artifact,
            CoachConfig(band_position_m=cfg.band_position_m,
                        band_orientation_rad=cfg.band_orientation_rad),
        )  # fmt: skip

    def anchor_time_s(self, phase: str | None) -> float:
        """Time of the artifact's first frame in ``phase`` [s] (0 for None); computed once."""
        if phase not in self._anchors:
            self._anchors[phase] = self._first_frame_time_s(phase)
        return self._anchors[phase]

    def _first_frame_time_s(self, phase: str | None) -> float:
        if phase is None:
            return 0.0
        names = list(self.artifact.phase_names)
        if phase not in names:
            raise ValueError(
                f"the task's reference starts at phase '{phase}', which the oracle artifact "
                f"(phases {names}) does not have: pass the artifact of the task's own reference"
            )
        ref = self.artifact.reference
        return float(np.flatnonzero(np.asarray(ref.phase) == names.index(phase))[0] * ref.dt)

    def __call__(self, env: G1VecEnv) -> torch.Tensor:
        """Wrench (N, 6) [N, Nm] for the env's current state."""
        command = env.command_gen
        time_s = command.reference_time_s()
        if time_s is None:
            raise ValueError(
                f"task '{env.task.name}' has no time-indexed reference (its command gives no "
                "reference_time_s), so an artifact's coach cannot follow it: use --warmstart "
                "posture, or the task whose reference the artifact solved (dance, backflip)"
            )
        time_s = (time_s + self.anchor_time_s(command.reference_anchor_phase)).clamp_min(0.0)
        s = env.env_state
        omega_w = quat_rotate(s.base_quat_w, s.base_ang_vel_b)
        wrench_w = self.coach.wrench(s.base_pos_w, s.base_quat_w, s.base_lin_vel_w, omega_w,
                                     time_s.float())  # fmt: skip
        wrench = world_to_heading(wrench_w.float(), s.base_quat_w)
        bound = s.assist_bound
        return torch.maximum(torch.minimum(wrench, bound), -bound)


def _posture(env: G1VecEnv) -> Callable[[G1VecEnv], torch.Tensor]:
    coach = PostureCoach.for_env(env)
    return lambda e: coach(e.env_state)


COACHES = {"posture": _posture}
"""Built-in coaches by name (``--warmstart posture``)."""
