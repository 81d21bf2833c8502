"""The physics behind :class:`rl.envs.vec_env.G1VecEnv`: the :class:`Physics` interface the env
talks to, in torch tensors, and :class:`MujocoRolloutPhysics`, MuJoCo C on CPU.

MuJoCo C design (measured, see ``docs/environments.md``): the batch state is one (N, nstate) numpy
array of ``mjSTATE_FULLPHYSICS`` rows. Each policy step makes *one* call of a persistent
``mujoco.rollout.Rollout`` that advances every env ``decimation`` physics steps in C threads, with
per-env ``MjModel`` copies (domain randomisation) and a control array holding the 29 joint targets
and the pelvis ``xfrc_applied``. The torch tensors the env reads and edits view the same memory.

MuJoCo Warp (:class:`rl.envs.warp_physics.WarpPhysics`, the ``gpu`` extra) implements the same
interface on Warp's CPU or CUDA device; the env's parts, the tasks and their terms stay as they are.
"""

from __future__ import annotations

from typing import Any, Protocol

import mujoco
import numpy as np
import torch
from mujoco import rollout

from rl.envs.model import CONTROL_SPEC, STATE_SPEC, ModelLayout, model_layout
from rl.envs.state import quat_rotate_inverse
from robots import g1


class Physics(Protocol):
    """N G1 robots stepped together; every tensor has a leading env axis N.

    ``qpos`` (N, 36) [p_w, quat_w wxyz, 29 joints] and ``qvel`` (N, 35) [v_w, omega_b, 29 joint
    rates] are views of the simulator's state (float64 on MuJoCo C, on the CPU; float32 on Warp,
    on Warp's device, which is the env's): writing into them edits the next step's start (pushes,
    tests). ``models[i]`` is the model env ``i`` steps with (the randomiser's copies,
    possibly shared between envs).
    """

    num_envs: int  # N [-]
    decimation: int  # physics steps per policy step [-]
    physics_dt_s: float  # one physics step [s]
    model: mujoco.MjModel  # the nominal model (sizes, masses, names)
    layout: ModelLayout  # where things live in state, control and sensor rows
    models: list[mujoco.MjModel]  # (N,) the model of each env (copies may be shared)
    qpos: torch.Tensor  # (N, 36) float64 view
    qvel: torch.Tensor  # (N, 35) float64 view
    stand_qpos: torch.Tensor  # (36,) float64 standing keyframe
    stand_qvel: torch.Tensor  # (35,) float64
    diverged_total: int  # rows replaced since the start because they diverged [-]
    diverged_counter: int | torch.Tensor  # the same, as the env logs it (Warp: on the device) [-]

    def set_controls(self, joint_targets_rad: torch.Tensor, wrench_w: torch.Tensor) -> None:
        """Hold PD targets (N, 29) [rad] and the pelvis wrench (N, 6) (world-frame force [N],
        torque [Nm] at the pelvis centre of mass) over the next :meth:`step`."""

    def step(self) -> torch.Tensor:
        """Advance every env ``decimation`` physics steps; returns (N,) bool, the rows that
        diverged (their state is the standing keyframe until the env resets them)."""

    def fault_flags(self) -> dict[str, torch.Tensor]:
        """Device scalars that a step left for the env to bring to the host with its own batch of
        host values (no wait of its own for the device); empty where there are none."""

    def raise_on_faults(self, host: dict[str, float]) -> None:
        """Raise if ``host`` (:meth:`fault_flags` on the host) names a fault that leaves every
        row's step wrong."""

    def reset_rows(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Start ``env_ids`` (M,) from ``qpos`` (M, 36), ``qvel`` (M, 35) at time 0; their
        sensors are recomputed (at the standing PD targets, no wrench)."""

    def read(self) -> dict[str, Any]:
        """The robot fields of :class:`rl.envs.state.EnvState` (float32 tensors, fresh copies)."""

    def state_dict(self) -> dict[str, Any]:
        """State and sensor rows and the divergence count (exact resume)."""

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output of a physics of the same size."""

    def close(self) -> None:
        """Release threads and device memory."""


def robot_fields(
    layout: ModelLayout, qpos: torch.Tensor, qvel: torch.Tensor, sensordata: torch.Tensor
) -> dict[str, Any]:
    """The robot fields of :class:`rl.envs.state.EnvState` from state and sensor rows, the same
    for every backend: ``qpos`` (N, 36), ``qvel`` (N, 35), ``sensordata`` (N, nsensordata) of any
    float dtype; returns float32 tensors (fresh, never views of the simulator's memory)."""
    lay = layout
    # float32 copies: .float() of a float32 view (Warp) would return the view itself
    qpos, qvel, sens = (t.to(torch.float32, copy=True) for t in (qpos, qvel, sensordata))
    quat = qpos[:, 3:7]
    lin_vel_w = qvel[:, 0:3]
    gravity_dir_w = torch.tensor([0.0, 0.0, -1.0], device=qpos.device).expand(qpos.shape[0], 3)
    return {
        "base_pos_w": qpos[:, 0:3],
        "base_quat_w": quat,
        "base_lin_vel_w": lin_vel_w,
        "base_lin_vel_b": quat_rotate_inverse(quat, lin_vel_w),
        "base_ang_vel_b": qvel[:, 3:6],
        "projected_gravity_b": quat_rotate_inverse(quat, gravity_dir_w),
        "joint_pos_rad": qpos[:, 7:],
        "joint_vel_rps": qvel[:, 6:],
        "joint_torque_nm": sens[:, lay.torque],
        "foot_contact_force_n": sens[:, list(lay.foot_touch)],
        "foot_pos_w": torch.stack([sens[:, lay.foot_pos[0]], sens[:, lay.foot_pos[1]]], dim=1),
        "foot_vel_w": torch.stack([sens[:, lay.foot_vel[0]], sens[:, lay.foot_vel[1]]], dim=1),
        "body_ground_contact": sens[:, lay.contact] > 0.5,
        "contact_body_names": lay.contact_bodies,
        **{
            name: sens[:, torch.as_tensor(cols, dtype=torch.long, device=sens.device)]
            for name, cols in (
                ("body_pos_w", lay.body_pos),
                ("body_quat_w", lay.body_quat),
                ("body_lin_vel_w", lay.body_lin_vel),
                ("body_ang_vel_w", lay.body_ang_vel),
            )
        },
    }


class MujocoRolloutPhysics:
    """:class:`Physics` on MuJoCo C: one threaded ``mujoco.rollout`` call per policy step (CPU).

    ``state``, ``control`` and ``sensordata`` are the numpy rows the rollout reads and writes
    ((N, nstate), (N, decimation, ncontrol), (N, nsensordata)); the torch views share their memory.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        models: list[mujoco.MjModel],
        decimation: int,
        num_threads: int,
        max_abs_qvel: float,
    ) -> None:
        """``model``: the nominal model; ``models`` (N,): the model of each env (N = len)."""
        n = self.num_envs = len(models)
        self.decimation = decimation
        self.max_abs_qvel = max_abs_qvel  # rows with a larger |qvel| entry diverged [m/s, rad/s]
        self.model = model
        self.layout = lay = model_layout(model)
        self.physics_dt_s = float(model.opt.timestep)
        self.models = models
        self.num_threads = num_threads
        self._rollout: rollout.Rollout | None = rollout.Rollout(nthread=num_threads)
        self.physics_datas = [mujoco.MjData(model) for _ in range(num_threads)]
        self._scratch = mujoco.MjData(model)
        self.state = np.tile(lay.stand_state, (n, 1))
        self.control = np.zeros((n, decimation, lay.ncontrol))
        self.sensordata = np.zeros((n, lay.nsensordata))
        self._state_out = np.zeros((n, decimation, lay.nstate))
        self._sensor_out = np.zeros((n, decimation, lay.nsensordata))
        self.state_t = torch.from_numpy(self.state)
        self._control_t = torch.from_numpy(self.control)
        self._sensor_t = torch.from_numpy(self.sensordata)
        self.qpos, self.qvel = self.state_t[:, lay.qpos], self.state_t[:, lay.qvel]
        self.stand_qpos = torch.as_tensor(lay.stand_state[lay.qpos], dtype=torch.float64)
        self.stand_qvel = torch.as_tensor(lay.stand_state[lay.qvel], dtype=torch.float64)
        self.diverged_total = 0

    def set_controls(self, joint_targets_rad: torch.Tensor, wrench_w: torch.Tensor) -> None:
        """Write the joint targets and the pelvis ``xfrc_applied`` of every substep."""
        lay = self.layout
        self._control_t[:, :, lay.ctrl] = joint_targets_rad.unsqueeze(1).double()
        self._control_t[:, :, lay.pelvis_wrench] = wrench_w.unsqueeze(1).double()

    def step(self) -> torch.Tensor:
        """One rollout call; rows that were broken before it or diverged in it are counted and
        replaced by the standing keyframe (never fed to MuJoCo, never returned as NaN)."""
        lay = self.layout
        bad_in = torch.from_numpy(~np.isfinite(self.state).all(axis=1))
        if bad_in.any():
            self.state[bad_in.numpy()] = lay.stand_state
        time_in = self.state[:, lay.time].copy()
        self._rollout.rollout(
            self.models,
            self.physics_datas,
            self.state,
            self.control,
            control_spec=int(CONTROL_SPEC),
            skip_checks=True,
            nstep=self.decimation,
            initial_warmstart=None,
            state=self._state_out,
            sensordata=self._sensor_out,
            chunk_size=None,
        )
        self.state[:] = self._state_out[:, -1]
        self.sensordata[:] = self._sensor_out[:, -1]
        diverged = bad_in | self._diverged(time_in)
        num_diverged = int(diverged.sum())
        if num_diverged:
            rows = diverged.numpy()
            self.state[rows] = lay.stand_state  # placeholder until the env resets them
            self.sensordata[rows] = 0.0
            self.diverged_total += num_diverged
        return diverged

    @property
    def diverged_counter(self) -> int:
        """:attr:`diverged_total` (a host count here)."""
        return self.diverged_total

    def fault_flags(self) -> dict[str, torch.Tensor]:
        """None: a MuJoCo C step fails row by row (:meth:`step`'s ``diverged``)."""
        return {}

    def raise_on_faults(self, host: dict[str, float]) -> None:
        """Nothing to raise (:meth:`fault_flags` is empty)."""

    def _diverged(self, time_in: np.ndarray) -> torch.Tensor:
        """Rows that went non-finite, blew up, or were silently reset by MuJoCo's own checks
        (which restarts the clock, so the time no longer advanced by decimation * dt)."""
        lay = self.layout
        finite = np.isfinite(self.state).all(axis=1) & np.isfinite(self.sensordata).all(axis=1)
        expected = time_in + self.decimation * self.physics_dt_s
        clock_ok = np.abs(self.state[:, lay.time] - expected) < 0.5 * self.physics_dt_s
        with np.errstate(invalid="ignore"):
            calm = np.abs(self.state[:, lay.qvel]).max(axis=1) < self.max_abs_qvel
        return torch.from_numpy(~(finite & clock_ok & calm))

    def reset_rows(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Full state rows from the keyframe with ``qpos``, ``qvel`` and time 0; fresh sensors."""
        lay = self.layout
        rows = torch.as_tensor(lay.stand_state, dtype=torch.float64).repeat(env_ids.numel(), 1)
        rows[:, lay.qpos], rows[:, lay.qvel], rows[:, lay.time] = qpos, qvel, 0.0
        self.state_t[env_ids] = rows
        self.refresh_sensors(env_ids)

    def refresh_sensors(self, env_ids: torch.Tensor) -> None:
        """Recompute the sensor rows of ``env_ids`` (contacts, torques at the stand targets)."""
        data = self._scratch
        for i in env_ids.tolist():
            model = self.models[i]
            mujoco.mj_setState(model, data, self.state[i], STATE_SPEC)
            data.ctrl[:] = g1.STAND_JOINT_POS_RAD
            data.xfrc_applied[:] = 0.0
            mujoco.mj_forward(model, data)
            self.sensordata[i] = data.sensordata

    def read(self) -> dict[str, Any]:
        """Pelvis pose and velocities, joints, torques, sole forces / poses, link contacts."""
        lay = self.layout
        return robot_fields(
            lay, self.state_t[:, lay.qpos], self.state_t[:, lay.qvel], self._sensor_t
        )

    def state_dict(self) -> dict[str, Any]:
        """State and sensor rows, divergence count."""
        return {
            "state": self.state.copy(),
            "sensordata": self.sensordata.copy(),
            "diverged_total": self.diverged_total,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore rows of the same shape (else: resume with the run's own config)."""
        if state["state"].shape != self.state.shape:
            raise ValueError(
                f"env checkpoint holds {state['state'].shape[0]} envs of state width "
                f"{state['state'].shape[1]}, this env has {self.num_envs} x {self.state.shape[1]}: "
                "resume with the run's own config"
            )
        self.state[:] = state["state"]
        self.sensordata[:] = state["sensordata"]
        self.diverged_total = int(state["diverged_total"])

    def close(self) -> None:
        """Stop the thread pool."""
        if self._rollout is not None:
            self._rollout.close()
            self._rollout = None
