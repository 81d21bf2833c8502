"""``G1VecEnv``: N G1 instances stepped together in MuJoCo's C thread pool, as an rsl-rl ``VecEnv``.

Design (measured, see ``docs/environments.md``): the batch state is one (N, nstate) numpy array of
``mjSTATE_FULLPHYSICS`` rows. Each policy step makes *one* call of a persistent
``mujoco.rollout.Rollout`` that advances every env ``decimation`` physics steps in C threads, with
per-env ``MjModel`` copies (domain randomisation) and a control array holding the 29 joint targets
and the pelvis ``xfrc_applied`` (the assist wrench). Observations, rewards, terminations, pushes and
resets are torch operations over the whole batch viewing the same memory (no per-env Python loop,
except for the few envs that reset in a step).
"""

from __future__ import annotations

import copy
import math
import os
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import torch
from mujoco import rollout
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rl import rewards
from rl.assist import WRENCH_DIM, AssistState
from rl.envs.buffers import HistoryBuffer
from rl.envs.config import EnvConfig
from rl.envs.model import CONTROL_SPEC, STATE_SPEC, build_physics_model, model_layout
from rl.envs.randomization import ModelRandomizer, nominal_params, sample_params
from rl.envs.state import EnvState, quat_multiply, quat_rotate_inverse
from robots import g1
from robots.mujoco_model import MujocoModelConfig

if TYPE_CHECKING:
    from rl.tasks.base import Task

GRAVITY_MPS2 = 9.81


class G1VecEnv(VecEnv):
    """Batched G1 environment implementing ``rsl_rl.env.VecEnv`` (see ``rl_contract.md``).

    Actions (N, 35): [:, :29] motion action a (joint target = stand + ACTION_SCALE_RAD * a),
    [:, 29:] raw assist head output, applied as F = mask * eta[phase] * tanh(raw) to the pelvis.
    """

    def __init__(
        self, cfg: EnvConfig, task: Task, model_cfg: MujocoModelConfig = MujocoModelConfig()
    ) -> None:
        self.cfg = cfg
        self.task = task
        self.device = "cpu"
        self.num_envs = n = cfg.num_envs
        self.num_actions = g1.NUM_JOINTS + WRENCH_DIM
        self.num_phases = task.num_phases
        self.generator = torch.Generator().manual_seed(cfg.seed)

        self.model = build_physics_model(model_cfg)
        self.layout = lay = model_layout(self.model)
        self.physics_dt_s = float(self.model.opt.timestep)
        self.step_dt_s = self.physics_dt_s * cfg.decimation
        self.max_episode_length = math.ceil(cfg.episode_length_s / self.step_dt_s)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long)
        # Steps since each env's actual reset; runners may overwrite episode_length_buf.
        self._lived_steps = torch.zeros(n, dtype=torch.long)
        self.total_mass_kg = float(self.model.body_subtreemass[0])

        self._randomizer = ModelRandomizer.for_model(self.model, cfg.payload_body)
        if cfg.randomize:
            self._randomizer.check_payload_range(cfg.payload_mass_range_kg)
        self.models = (
            [copy.copy(self.model) for _ in range(n)] if cfg.randomize else [self.model] * n
        )
        self.num_threads = cfg.num_threads or os.cpu_count() or 1
        self._rollout = rollout.Rollout(nthread=self.num_threads)
        self.physics_datas = [mujoco.MjData(self.model) for _ in range(self.num_threads)]
        self._scratch = mujoco.MjData(self.model)

        # Batch buffers (numpy) and torch views of the same memory.
        self.state = np.tile(lay.stand_state, (n, 1))
        self.control = np.zeros((n, cfg.decimation, lay.ncontrol))
        self._state_out = np.zeros((n, cfg.decimation, lay.nstate))
        self._sensor_out = np.zeros((n, cfg.decimation, lay.nsensordata))
        self.sensordata = np.zeros((n, lay.nsensordata))
        self._state_t = torch.from_numpy(self.state)
        self._control_t = torch.from_numpy(self.control)
        self._sensor_t = torch.from_numpy(self.sensordata)

        self._stand_rad = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32)
        self._action_scale = torch.as_tensor(g1.ACTION_SCALE_RAD, dtype=torch.float32)
        self._effort_nm = torch.as_tensor(g1.EFFORT_LIMIT_NM, dtype=torch.float32)
        self._gravity_dir_w = torch.tensor([0.0, 0.0, -1.0]).expand(n, 3)
        self.action = torch.zeros(n, g1.NUM_JOINTS)
        self.last_action = torch.zeros(n, g1.NUM_JOINTS)
        self.applied_wrench = torch.zeros(n, WRENCH_DIM)
        self.assist_mask = torch.ones(n, WRENCH_DIM)
        self.phase = torch.zeros(n, dtype=torch.long)
        self.randomization_params = nominal_params(n, self.model)
        self._push_timer_s = torch.zeros(n)
        self.diverged_total = 0

        task.bind(n, self.generator, self.max_episode_length)
        self.assist = AssistState(
            task.default_assist_bound(),
            cfg.assist_enabled,
            cfg.random_mask_prob,
            cfg.less_assist_reward,
            self.generator,
        )
        self._reward_terms = task.reward_terms()
        self._noise_scale = None  # set after the first observation fixes P
        self.env_state: EnvState
        self.history: HistoryBuffer | None = None
        self._reset_envs(torch.arange(n))
        self.env_state = self._read_state()
        self.phase = task.phase(self.env_state)
        self._obs = self._observations(reset_ids=torch.arange(n))

    # ---------------------------------------------------------------- runner-facing setters
    def set_assist_bound(self, eta: torch.Tensor) -> None:
        """Set eta (num_phases, 6) [N, Nm], the per-phase, per-axis wrench bound."""
        self.assist.set_bound(torch.as_tensor(eta).detach().cpu())

    def set_assist_enabled(self, enabled: bool) -> None:
        """Switch the assist wrench on or off (off: F = 0 whatever the head outputs)."""
        self.assist.enabled = bool(enabled)

    def set_random_mask_prob(self, zeta: float) -> None:
        """Set zeta, the probability of dropping each wrench component every step."""
        self.assist.set_mask_prob(zeta)

    def set_less_assist_reward(self, enabled: bool) -> None:
        """Add (or stop adding) the less-assist reward exp(-2|F|/|eta|) to the task reward."""
        self.assist.less_assist_reward = bool(enabled)

    # ---------------------------------------------------------------- VecEnv API
    def get_observations(self) -> TensorDict:
        """Current observation groups (see ``rl_contract.md``)."""
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Apply actions (N, 35) for one policy step; returns (obs, rewards, dones, extras)."""
        n, lay, cfg = self.num_envs, self.layout, self.cfg
        if actions.shape != (n, self.num_actions):
            raise ValueError(
                f"G1VecEnv.step expects actions of shape ({n}, {self.num_actions}) = (num_envs, "
                f"29 joint + 6 assist), got {tuple(actions.shape)}."
            )
        actions = actions.detach().to("cpu", torch.float32)
        # A non-finite action would make MuJoCo reset the row; zero it and report how often.
        nonfinite_actions = int((~torch.isfinite(actions).all(dim=-1)).sum())
        if nonfinite_actions:
            actions = torch.nan_to_num(actions, nan=0.0, posinf=0.0, neginf=0.0)
        actions = actions.clamp(-cfg.clip_actions, cfg.clip_actions)
        self.action = actions[:, : g1.NUM_JOINTS]
        applied_phase = self.phase
        wrench, bound, self.assist_mask = self.assist.wrench(
            actions[:, g1.NUM_JOINTS :], applied_phase
        )
        self.applied_wrench = wrench.clone()

        targets = self._stand_rad + self._action_scale * self.action
        self._control_t[:, :, lay.ctrl] = targets.unsqueeze(1).double()
        self._control_t[:, :, lay.pelvis_wrench] = wrench.unsqueeze(1).double()
        self._push()

        # Rows already broken (e.g. written from outside) never enter the physics.
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
            nstep=cfg.decimation,
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
            self.state[rows] = lay.stand_state  # placeholder until their reset below
            self.sensordata[rows] = 0.0
            self.diverged_total += num_diverged

        self.episode_length_buf += 1
        self._lived_steps += 1
        state = self._read_state()
        self.env_state = state
        terminated = self.task.terminated(state) | diverged
        time_outs = (self.episode_length_buf >= self.max_episode_length) & ~terminated
        dones = terminated | time_outs

        names = list(self._reward_terms)
        terms = [t.fn(state) * (t.weight * self.step_dt_s) for t in self._reward_terms.values()]
        if self.assist.less_assist_reward:
            names.append("less_assist")
            weight = self.task.less_assist_weight * self.step_dt_s
            terms.append(rewards.less_assist(wrench, bound) * weight)
        weighted = torch.stack(terms)  # (terms, N)
        reward = weighted.sum(dim=0)
        log: dict[str, float] = {
            f"Reward/{name}": value
            for name, value in zip(names, weighted.mean(dim=1).tolist(), strict=True)
        }
        reward = torch.where(diverged, torch.zeros_like(reward), torch.nan_to_num(reward))

        done_ids = dones.nonzero().flatten()
        if done_ids.numel():
            self.task.on_episodes_end(done_ids, time_outs[done_ids], self._lived_steps[done_ids])
        self.last_action = self.action.clone()
        if done_ids.numel():
            self._reset_envs(done_ids)
            state = self._read_state()
            self.env_state = state
        self.phase = self.task.phase(state)
        self._obs = self._observations(reset_ids=done_ids)

        log["Episode/diverged_envs"] = float(num_diverged)
        log["Episode/diverged_envs_total"] = float(self.diverged_total)
        log["Episode/nonfinite_action_envs"] = float(nonfinite_actions)
        log["Episode/terminated"] = float(terminated.float().mean())
        log["Assist/force_norm_n"] = float(wrench[:, :3].norm(dim=-1).mean())
        log["Assist/torque_norm_nm"] = float(wrench[:, 3:].norm(dim=-1).mean())
        progress = self.task.skill_progress()
        log["Episode/skill_progress"] = progress
        extras = {
            "time_outs": time_outs,
            "log": log,
            "assist": {"applied_wrench": wrench, "bound": bound, "phase": applied_phase},
            "skill_progress": progress,
        }
        return self._obs, reward, dones, extras

    def close(self) -> None:
        """Stop the physics thread pool."""
        if self._rollout is not None:
            self._rollout.close()
            self._rollout = None

    # ---------------------------------------------------------------- internals
    def _push(self) -> None:
        """Velocity kicks: envs whose push timer ran out get a random horizontal base velocity."""
        if not self.cfg.pushes:
            return
        self._push_timer_s -= self.step_dt_s
        ids = (self._push_timer_s <= 0).nonzero().flatten()
        if ids.numel() == 0:
            return
        vmax = self.cfg.push_velocity_xy_mps
        kick = (2 * torch.rand(ids.numel(), 2, generator=self.generator) - 1) * vmax
        qv0 = self.layout.qvel.start
        self._state_t[ids, qv0 : qv0 + 2] += kick.double()
        self._push_timer_s[ids] = self._sample_push_interval(ids.numel())

    def _sample_push_interval(self, num: int) -> torch.Tensor:
        low, high = self.cfg.push_interval_range_s
        return low + (high - low) * torch.rand(num, generator=self.generator)

    def _diverged(self, time_in: np.ndarray) -> torch.Tensor:
        """Rows that went non-finite, blew up, or were silently reset by MuJoCo's own checks
        (which restarts the clock, so the time no longer advanced by decimation * dt)."""
        lay = self.layout
        finite = np.isfinite(self.state).all(axis=1) & np.isfinite(self.sensordata).all(axis=1)
        expected = time_in + self.cfg.decimation * self.physics_dt_s
        clock_ok = np.abs(self.state[:, lay.time] - expected) < 0.5 * self.physics_dt_s
        with np.errstate(invalid="ignore"):
            calm = np.abs(self.state[:, lay.qvel]).max(axis=1) < self.cfg.max_abs_qvel
        return torch.from_numpy(~(finite & clock_ok & calm))

    def _reset_envs(self, env_ids: torch.Tensor) -> None:
        """Put ``env_ids`` (M,) back to a (noisy) standing state with fresh randomisation."""
        cfg, lay = self.cfg, self.layout
        m = env_ids.numel()
        gen = self.generator
        rows = torch.as_tensor(lay.stand_state, dtype=torch.float64).repeat(m, 1)
        q0, v0 = lay.qpos.start, lay.qvel.start
        joint_noise = (2 * torch.rand(m, g1.NUM_JOINTS, generator=gen) - 1) * (
            cfg.reset_joint_pos_noise_rad
        )
        rows[:, q0 + 7 : q0 + 7 + g1.NUM_JOINTS] += joint_noise.double()
        if cfg.reset_random_yaw:
            yaw = (2 * torch.rand(m, generator=gen) - 1) * math.pi
            yaw_quat = torch.stack(
                [torch.cos(yaw / 2), torch.zeros(m), torch.zeros(m), torch.sin(yaw / 2)], dim=-1
            )
            rows[:, q0 + 3 : q0 + 7] = quat_multiply(yaw_quat.double(), rows[:, q0 + 3 : q0 + 7])
        base_vel = (2 * torch.rand(m, 6, generator=gen) - 1) * cfg.reset_base_vel_noise_mps
        rows[:, v0 : v0 + 6] = base_vel.double()
        rows[:, lay.time] = 0.0
        self.task.reset_state(env_ids, rows[:, lay.qpos], rows[:, lay.qvel])  # views: in place
        self._state_t[env_ids] = rows

        if cfg.randomize:
            params = sample_params(m, cfg, gen)
            self.randomization_params[env_ids] = params
            for i, row in zip(env_ids.tolist(), params.double().numpy(), strict=True):
                self._randomizer.apply(self.models[i], row)
        self._refresh_sensors(env_ids)

        self.episode_length_buf[env_ids] = 0
        self._lived_steps[env_ids] = 0
        self.action[env_ids] = 0.0
        self.last_action[env_ids] = 0.0
        self.applied_wrench[env_ids] = 0.0
        self._push_timer_s[env_ids] = self._sample_push_interval(m)
        self.task.reset(env_ids)

    def _refresh_sensors(self, env_ids: torch.Tensor) -> None:
        """Recompute the sensor rows of freshly reset envs (contacts, torques at the stand targets)."""
        data = self._scratch
        for i in env_ids.tolist():
            model = self.models[i]
            mujoco.mj_setState(model, data, self.state[i], STATE_SPEC)
            data.ctrl[:] = g1.STAND_JOINT_POS_RAD
            data.xfrc_applied[:] = 0.0
            mujoco.mj_forward(model, data)
            self.sensordata[i] = data.sensordata

    def _read_state(self) -> EnvState:
        """Batch state as float32 tensors from the state and sensor rows."""
        lay = self.layout
        qpos = self._state_t[:, lay.qpos].float()
        qvel = self._state_t[:, lay.qvel].float()
        sens = self._sensor_t.float()
        quat = qpos[:, 3:7]
        lin_vel_w = qvel[:, 0:3]
        gravity_w = self._gravity_dir_w
        foot_pos = torch.stack([sens[:, lay.foot_pos[0]], sens[:, lay.foot_pos[1]]], dim=1)
        bound = self.assist.bound[self.phase]
        return EnvState(
            base_pos_w=qpos[:, 0:3],
            base_quat_w=quat,
            base_lin_vel_w=lin_vel_w,
            base_lin_vel_b=quat_rotate_inverse(quat, lin_vel_w),
            base_ang_vel_b=qvel[:, 3:6],
            projected_gravity_b=quat_rotate_inverse(quat, gravity_w),
            joint_pos_rad=qpos[:, 7:],
            joint_vel_rps=qvel[:, 6:],
            joint_torque_nm=sens[:, lay.torque],
            foot_contact_force_n=sens[:, list(lay.foot_touch)],
            foot_pos_w=foot_pos,
            action=self.action,
            last_action=self.last_action,
            applied_wrench=self.applied_wrench,
            assist_bound=bound,
            episode_time_s=self.episode_length_buf.float() * self.step_dt_s,
        )

    def _noise(self, width: int) -> torch.Tensor:
        """Per-column uniform noise amplitude of the policy observation (width P)."""
        cfg = self.cfg
        j = g1.NUM_JOINTS
        scale = torch.zeros(width)
        if cfg.noise:
            scale[0:3] = cfg.noise_ang_vel_rps
            scale[3:6] = cfg.noise_gravity
            scale[6 : 6 + j] = cfg.noise_joint_pos_rad
            scale[6 + j : 6 + 2 * j] = cfg.noise_joint_vel_rps
        return scale

    def _observations(self, reset_ids: torch.Tensor) -> TensorDict:
        """Build all observation groups from :attr:`env_state`; fill the history of reset envs."""
        s = self.env_state
        n = self.num_envs
        commands = self.task.commands(s)
        clean = torch.cat(
            [
                s.base_ang_vel_b,
                s.projected_gravity_b,
                s.joint_pos_rad - self._stand_rad,
                s.joint_vel_rps,
                self.last_action,
                commands,
            ],
            dim=-1,
        )
        if self._noise_scale is None:
            self._noise_scale = self._noise(clean.shape[1])
        noisy = clean + (2 * torch.rand(clean.shape, generator=self.generator) - 1) * (
            self._noise_scale
        )
        if self.history is None:
            self.history = HistoryBuffer(n, self.cfg.history_length, clean.shape[1])
        self.history.push(noisy)
        if reset_ids.numel():
            self.history.fill(reset_ids, noisy[reset_ids])
        weight_n = self.total_mass_kg * GRAVITY_MPS2
        phase_one_hot = torch.nn.functional.one_hot(self.phase, self.num_phases).float()
        privileged = torch.cat(
            [
                s.base_lin_vel_b,
                self.assist.bound[self.phase],
                self.randomization_params,
                phase_one_hot,
                s.foot_contact_force_n / weight_n,
                self.task.privileged_extras(s),
            ],
            dim=-1,
        )
        feet_rel_b = torch.cat(
            [quat_rotate_inverse(s.base_quat_w, s.foot_pos_w[:, k] - s.base_pos_w) for k in (0, 1)],
            dim=-1,
        )
        critic = torch.cat(
            [
                clean,
                privileged,
                s.base_pos_w[:, 2:3],
                feet_rel_b,
                self.applied_wrench / weight_n,
                s.joint_torque_nm / self._effort_nm,
            ],
            dim=-1,
        )
        return TensorDict(
            {
                "policy": noisy,
                "history": self.history.flat().clone(),
                "privileged": privileged,
                "critic": critic,
                "base_lin_vel": s.base_lin_vel_b.clone(),
                "policy_clean": clean,
            },
            batch_size=[n],
        )
