"""``G1VecEnv``: N G1 instances stepped together in MuJoCo's C thread pool, as an rsl-rl ``VecEnv``.

Design (measured, see ``docs/environments.md``): the batch state is one (N, nstate) numpy array of
``mjSTATE_FULLPHYSICS`` rows. Each policy step makes *one* call of a persistent
``mujoco.rollout.Rollout`` that advances every env ``decimation`` physics steps in C threads, with
per-env ``MjModel`` copies (domain randomisation) and a control array holding the 29 joint targets
and the pelvis ``xfrc_applied`` (the assist wrench). Observations, rewards, terminations, pushes and
resets are torch operations over the whole batch viewing the same memory (no per-env Python loop,
except for the few envs that reset in a step).

Everything task-specific comes from a :class:`rl.tasks.config.TaskConfig`: the physics scene,
initial-state distribution, pushes, randomisation ranges, named observation / reward / termination
terms, command, phases and skill measure. This module never branches on a task. The A2CF
curriculum (Algorithm 1) runs inside the env as an iteration-rate event
(:class:`rl.curriculum.CurriculumEvent`), so training uses rsl-rl's own ``OnPolicyRunner.learn``.
"""

from __future__ import annotations

import copy
import math
import os
from typing import Any

import mujoco
import numpy as np
import torch
from mujoco import rollout
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rl import rewards
from rl.assist import DEFAULT_RANDOM_MASK_PROB, WRENCH_DIM, AssistState
from rl.curriculum import WRENCH_AXES, CurriculumEvent
from rl.envs.buffers import HistoryBuffer
from rl.envs.config import EnvConfig
from rl.envs.model import CONTROL_SPEC, STATE_SPEC, build_physics_model, model_layout
from rl.envs.randomization import ModelRandomizer, nominal_params, sample_params
from rl.envs.state import (
    FOOT_CONTACT_THRESHOLD_N,
    EnvState,
    heading_to_world,
    quat_multiply,
    quat_rotate_inverse,
)
from rl.tasks.config import TaskConfig
from rl.tasks.terms import ObsGroup
from robots import g1
from robots.mujoco_model import MujocoModelConfig

GRAVITY_MPS2 = 9.81


class G1VecEnv(VecEnv):
    """Batched G1 environment implementing ``rsl_rl.env.VecEnv`` (see ``rl_contract.md``).

    Actions (N, 35): [:, :29] motion action a (joint target = stand + ACTION_SCALE_RAD * a),
    [:, 29:] raw assist head output, applied as F = mask * eta[phase] * tanh(raw) to the pelvis,
    F in the robot's heading frame (see :func:`rl.envs.state.heading_to_world`).
    """

    def __init__(
        self, cfg: EnvConfig, task: TaskConfig, model_cfg: MujocoModelConfig = MujocoModelConfig()
    ) -> None:
        self.cfg = cfg
        self.task = task
        self.device = "cpu"
        self.num_envs = n = cfg.num_envs
        self.num_actions = g1.NUM_JOINTS + WRENCH_DIM
        self.num_phases = task.num_phases
        self.phase_names = task.phase_names
        self.generator = torch.Generator().manual_seed(cfg.seed)

        scene = task.scene
        model_cfg = MujocoModelConfig(**{**model_cfg.__dict__, "floor": scene.floor})
        self.model = build_physics_model(model_cfg, scene.link_collisions, scene.terrain)
        self.layout = lay = model_layout(self.model)
        self.physics_dt_s = float(self.model.opt.timestep)
        self.step_dt_s = self.physics_dt_s * cfg.decimation
        self.max_episode_length = math.ceil(task.episode_length_s / self.step_dt_s)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long)
        # Steps since each env's actual reset; runners may overwrite episode_length_buf.
        self._lived_steps = torch.zeros(n, dtype=torch.long)
        self.total_mass_kg = float(self.model.body_subtreemass[0])
        self.weight_n = self.total_mass_kg * GRAVITY_MPS2

        rand = task.randomization
        self._randomizer = ModelRandomizer.for_model(self.model, rand.payload_body)
        if rand.enabled:
            self._randomizer.check_payload_range(rand.payload_mass_range_kg)
        # One model copy per env (redrawn at each reset), or G shared copies drawn once.
        self._per_env_models = rand.enabled and rand.model_groups == 0
        num_copies = (
            (n if rand.model_groups == 0 else min(rand.model_groups, n)) if rand.enabled else 1
        )
        self._model_copies = (
            [copy.copy(self.model) for _ in range(num_copies)] if rand.enabled else [self.model]
        )
        self.models = [self._model_copies[i % num_copies] for i in range(n)]
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
        self._last_joint_vel = torch.zeros(n, g1.NUM_JOINTS)
        self._joint_acc = torch.zeros(n, g1.NUM_JOINTS)
        self.foot_air_time_s = torch.zeros(n, 2)
        self.foot_contact_time_s = torch.zeros(n, 2)
        self.foot_last_air_time_s = torch.zeros(n, 2)
        self.foot_first_contact = torch.zeros(n, 2, dtype=torch.bool)
        self._joint_limits = torch.as_tensor(lay.joint_range_rad, dtype=torch.float32)

        self.command_gen = task.commands.build(n, self.generator)
        self.command = torch.zeros(n, task.commands.dim)
        self.phase_machine = task.phases.build(n, self.generator)
        self.skill = task.skill.build(self.max_episode_length)
        self.components = (self.command_gen, self.phase_machine, self.skill)
        self.assist = AssistState(
            task.default_assist_bound(),
            enabled=True,
            mask_prob=DEFAULT_RANDOM_MASK_PROB,
            less_assist_reward=False,
            generator=self.generator,
        )
        self.curriculum_event: CurriculumEvent | None = None
        self._noise_scale: dict[str, torch.Tensor] = {}
        self.env_state: EnvState
        self.history: HistoryBuffer | None = None
        if rand.enabled and not self._per_env_models:
            self._draw_group_models()
        self.reset_envs(torch.arange(n))

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

    def attach_curriculum(self, event: CurriculumEvent | None) -> None:
        """Run Algorithm 1 inside the env (every ``event.steps_per_iteration`` steps) and apply its
        current state now; ``None`` detaches it (the env keeps its last bounds)."""
        self.curriculum_event = event
        if event is not None:
            if event.curriculum.num_phases != self.num_phases:
                raise ValueError(
                    f"curriculum has {event.curriculum.num_phases} phases, task '{self.task.name}' "
                    f"has {self.num_phases}"
                )
            self._apply_curriculum()

    def _apply_curriculum(self) -> None:
        cur = self.curriculum_event.curriculum
        self.set_assist_bound(cur.eta)
        self.set_assist_enabled(cur.assist_enabled)
        self.set_less_assist_reward(cur.less_assist_reward)

    def reset_envs(self, env_ids: torch.Tensor) -> TensorDict:
        """Start new episodes for ``env_ids`` (M,) now: the task's initial-state distribution,
        fresh randomisation, components reset; the observations are rebuilt and returned. Other
        envs keep their state and history (their observations get fresh noise)."""
        env_ids = torch.as_tensor(env_ids, dtype=torch.long)
        self._reset_envs(env_ids)
        self.env_state = self._read_state()
        self.phase = self.phase_machine.update(self.env_state)
        self.command = self.command_gen.compute(self.env_state, 0.0)
        self.env_state = self._read_state()
        self._obs = self._observations(reset_ids=env_ids, push_history=self.history is None)
        return self._obs

    # ---------------------------------------------------------------- VecEnv API
    def get_observations(self) -> TensorDict:
        """Current observation groups (see ``rl_contract.md``)."""
        return self._obs

    def joint_targets_to_actions(self, joint_pos_rad: torch.Tensor) -> torch.Tensor:
        """The motion actions (N, 29) whose PD targets are ``joint_pos_rad`` (N, 29) [rad]."""
        return (joint_pos_rad.float() - self._stand_rad) / self._action_scale

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
        wrench_w = heading_to_world(wrench, self._state_t[:, lay.qpos][:, 3:7].float())
        self._control_t[:, :, lay.pelvis_wrench] = wrench_w.unsqueeze(1).double()
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
        self._update_kinematic_history()
        state = self._read_state()
        per_term = [term(state) for term in self.task.terminations]
        failed = torch.stack(per_term).any(dim=0) if per_term else torch.zeros(n, dtype=torch.bool)
        state.terminated = failed
        self.env_state = state
        terminated = failed | diverged
        time_outs = (self.episode_length_buf >= self.max_episode_length) & ~terminated
        dones = terminated | time_outs

        reward, log = self._reward(state, wrench, bound)
        reward = torch.where(diverged, torch.zeros_like(reward), torch.nan_to_num(reward))

        done_ids = dones.nonzero().flatten()
        if done_ids.numel():
            self.skill.on_episodes_end(
                done_ids, time_outs[done_ids], self._lived_steps[done_ids], state
            )
        self.last_action = self.action.clone()
        if done_ids.numel():
            self._reset_envs(done_ids)
            state = self._read_state(terminated=failed)
        self.phase = self.phase_machine.update(state)
        self.command = self.command_gen.compute(state, self.step_dt_s)
        # The state the next observations show: this one with the new phase and command.
        state.phase, state.command = self.phase, self.command
        state.assist_bound = self.assist.bound[self.phase]
        state.action, state.last_action = self.action, self.last_action
        self.env_state = state
        self._obs = self._observations(reset_ids=done_ids)

        for term, value in zip(self.task.terminations, per_term, strict=True):
            log[f"Termination/{term.name}"] = float(value.float().mean())
        log["Episode/diverged_envs"] = float(num_diverged)
        log["Episode/diverged_envs_total"] = float(self.diverged_total)
        log["Episode/nonfinite_action_envs"] = float(nonfinite_actions)
        log["Episode/terminated"] = float(terminated.float().mean())
        log["Assist/force_norm_n"] = float(wrench[:, :3].norm(dim=-1).mean())
        log["Assist/torque_norm_nm"] = float(wrench[:, 3:].norm(dim=-1).mean())
        log["Train/mean_step_reward"] = float(reward.mean())
        progress = self.skill.progress()
        log["Episode/skill_progress"] = progress
        for component in self.components:
            log.update(component.log())
        assist = {"applied_wrench": wrench, "bound": bound, "phase": applied_phase}
        if self.curriculum_event is not None:
            row = self.curriculum_event.on_step(assist, progress)
            if row is not None:
                self._apply_curriculum()
                log.update(self._curriculum_log(row))
        extras = {
            "time_outs": time_outs,
            "log": log,
            "assist": assist,
            "skill_progress": progress,
        }
        return self._obs, reward, dones, extras

    def close(self) -> None:
        """Stop the physics thread pool."""
        if self._rollout is not None:
            self._rollout.close()
            self._rollout = None

    # ---------------------------------------------------------------- checkpointing
    def state_dict(self) -> dict[str, Any]:
        """Everything that evolves while stepping: physics rows, RNG stream, counters, buffers,
        randomisation, task components and the curriculum event. With :meth:`load_state_dict`
        a resumed run continues bit for bit (on CPU)."""
        return {
            "state": self.state.copy(),
            "sensordata": self.sensordata.copy(),
            "generator": self.generator.get_state(),
            "episode_length_buf": self.episode_length_buf.clone(),
            "lived_steps": self._lived_steps.clone(),
            "action": self.action.clone(),
            "last_action": self.last_action.clone(),
            "applied_wrench": self.applied_wrench.clone(),
            "assist_mask": self.assist_mask.clone(),
            "phase": self.phase.clone(),
            "command": self.command.clone(),
            "randomization_params": self.randomization_params.clone(),
            "push_timer_s": self._push_timer_s.clone(),
            "history": self.history.buffer.clone(),
            "obs": self._obs.clone(),
            "diverged_total": self.diverged_total,
            "last_joint_vel": self._last_joint_vel.clone(),
            "joint_acc": self._joint_acc.clone(),
            "foot_timers": torch.stack(
                [self.foot_air_time_s, self.foot_contact_time_s, self.foot_last_air_time_s]
            ),
            "foot_first_contact": self.foot_first_contact.clone(),
            "assist": {
                "bound": self.assist.bound.clone(),
                "enabled": self.assist.enabled,
                "mask_prob": self.assist.mask_prob,
                "less_assist_reward": self.assist.less_assist_reward,
            },
            "command_gen": self.command_gen.state_dict(),
            "phase_machine": self.phase_machine.state_dict(),
            "skill": self.skill.state_dict(),
            "curriculum_event": (
                self.curriculum_event.state_dict() if self.curriculum_event is not None else None
            ),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output of an env of the same task, size and config."""
        if state["state"].shape != self.state.shape:
            raise ValueError(
                f"env checkpoint holds {state['state'].shape[0]} envs of state width "
                f"{state['state'].shape[1]}, this env has {self.num_envs} x {self.state.shape[1]}: "
                "resume with the run's own config"
            )
        self.state[:] = state["state"]
        self.sensordata[:] = state["sensordata"]
        self.generator.set_state(state["generator"])
        self.episode_length_buf = state["episode_length_buf"].clone()
        self._lived_steps = state["lived_steps"].clone()
        self.action = state["action"].clone()
        self.last_action = state["last_action"].clone()
        self.applied_wrench = state["applied_wrench"].clone()
        self.assist_mask = state["assist_mask"].clone()
        self.phase = state["phase"].clone()
        self.command = state["command"].clone()
        self.randomization_params = state["randomization_params"].clone()
        if self.task.randomization.enabled:
            params = self.randomization_params.double().numpy()
            for i, model in enumerate(self._model_copies):
                self._randomizer.apply(model, params[i])
        self._push_timer_s = state["push_timer_s"].clone()
        self.history.buffer = state["history"].clone()
        self._obs = state["obs"].clone()
        self.diverged_total = int(state["diverged_total"])
        self._last_joint_vel = state["last_joint_vel"].clone()
        self._joint_acc = state["joint_acc"].clone()
        timers = state["foot_timers"].clone()
        self.foot_air_time_s, self.foot_contact_time_s, self.foot_last_air_time_s = timers
        self.foot_first_contact = state["foot_first_contact"].clone()
        assist = state["assist"]
        self.assist.set_bound(assist["bound"])
        self.assist.enabled = bool(assist["enabled"])
        self.assist.set_mask_prob(assist["mask_prob"])
        self.assist.less_assist_reward = bool(assist["less_assist_reward"])
        self.command_gen.load_state_dict(state["command_gen"])
        self.phase_machine.load_state_dict(state["phase_machine"])
        self.skill.load_state_dict(state["skill"])
        if state["curriculum_event"] is not None:
            if self.curriculum_event is None:
                raise ValueError("env checkpoint has a curriculum; attach one before loading")
            self.curriculum_event.load_state_dict(state["curriculum_event"])
        self.env_state = self._read_state()

    # ---------------------------------------------------------------- internals
    def _reward(
        self, state: EnvState, wrench: torch.Tensor, bound: torch.Tensor
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """Weighted sum of the task's reward terms (+ less-assist when on) and their log."""
        dt = self.step_dt_s
        terms = self.task.rewards
        names = [t.name for t in terms]
        values = [t(state) * (t.weight * dt) for t in terms]
        if self.assist.less_assist_reward:
            names.append("less_assist")
            values.append(rewards.less_assist(wrench, bound) * (self.task.less_assist_weight * dt))
        weighted = torch.stack(values)  # (terms, N)
        log = {
            f"Reward/{name}": value
            for name, value in zip(names, weighted.mean(dim=1).tolist(), strict=True)
        }
        return weighted.sum(dim=0), log

    def _curriculum_log(self, row: dict[str, Any]) -> dict[str, float]:
        """TensorBoard scalars of one curriculum update (logged once, at the rollout's end)."""
        log = {
            "Curriculum/applied_force_n": float(row["applied_force_n"]),
            "Curriculum/skill_progress": float(row["skill_progress"]),
            "Curriculum/assist_enabled": float(row["assist_enabled"]),
            "Curriculum/less_assist_reward": float(row["less_assist_reward"]),
        }
        for phase, bounds, norm, applied in zip(
            self.phase_names, row["eta"], row["applied_norm"], row["applied_abs_per_axis"],
            strict=True,
        ):  # fmt: skip
            for axis, value, used in zip(WRENCH_AXES, bounds, applied, strict=True):
                log[f"Curriculum/eta_{phase}_{axis}"] = float(value)
                log[f"Curriculum/applied_abs_{phase}_{axis}"] = float(used)
            log[f"Curriculum/applied_wrench_norm_{phase}"] = float(norm)
        return log

    def _push(self) -> None:
        """Velocity kicks: envs whose push timer ran out get a random horizontal base velocity."""
        pushes = self.task.pushes
        if not pushes.enabled:
            return
        self._push_timer_s -= self.step_dt_s
        ids = (self._push_timer_s <= 0).nonzero().flatten()
        if ids.numel() == 0:
            return
        vmax = pushes.velocity_xy_mps
        kick = (2 * torch.rand(ids.numel(), 2, generator=self.generator) - 1) * vmax
        qv0 = self.layout.qvel.start
        self._state_t[ids, qv0 : qv0 + 2] += kick.double()
        self._push_timer_s[ids] = self._sample_push_interval(ids.numel())

    def _sample_push_interval(self, num: int) -> torch.Tensor:
        low, high = self.task.pushes.interval_range_s
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

    def _draw_group_models(self) -> None:
        """Shared-model randomisation: draw the G copies once; env i reports copy i % G."""
        g = len(self._model_copies)
        params = sample_params(g, self.task.randomization, self.generator)
        for model, row in zip(self._model_copies, params.double().numpy(), strict=True):
            self._randomizer.apply(model, row)
        self.randomization_params = params[torch.arange(self.num_envs) % g].clone()

    def _reset_envs(self, env_ids: torch.Tensor) -> None:
        """Put ``env_ids`` (M,) back to a state of the task's initial-state distribution, with
        fresh randomisation (per-env models)."""
        init, lay = self.task.initial_state, self.layout
        m = env_ids.numel()
        gen = self.generator
        rows = torch.as_tensor(lay.stand_state, dtype=torch.float64).repeat(m, 1)
        q0, v0 = lay.qpos.start, lay.qvel.start
        joint_noise = (2 * torch.rand(m, g1.NUM_JOINTS, generator=gen) - 1) * (
            init.joint_pos_noise_rad
        )
        rows[:, q0 + 7 : q0 + 7 + g1.NUM_JOINTS] += joint_noise.double()
        if init.random_yaw:
            yaw = (2 * torch.rand(m, generator=gen) - 1) * math.pi
            yaw_quat = torch.stack(
                [torch.cos(yaw / 2), torch.zeros(m), torch.zeros(m), torch.sin(yaw / 2)], dim=-1
            )
            rows[:, q0 + 3 : q0 + 7] = quat_multiply(yaw_quat.double(), rows[:, q0 + 3 : q0 + 7])
        base_vel = (2 * torch.rand(m, 6, generator=gen) - 1) * init.base_vel_noise
        rows[:, v0 : v0 + 6] = base_vel.double()
        rows[:, lay.time] = 0.0
        if init.reset_state is not None:
            init.reset_state(env_ids, rows[:, lay.qpos], rows[:, lay.qvel], gen)  # views: in place
        for component in self.components:
            component.reset_state(env_ids, rows[:, lay.qpos], rows[:, lay.qvel], gen)
        self._state_t[env_ids] = rows

        if self._per_env_models:
            params = sample_params(m, self.task.randomization, gen)
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
        self._last_joint_vel[env_ids] = self._state_t[env_ids][:, lay.qvel][:, 6:].float()
        self._joint_acc[env_ids] = 0.0
        self.foot_air_time_s[env_ids] = 0.0
        self.foot_contact_time_s[env_ids] = 0.0
        self.foot_last_air_time_s[env_ids] = 0.0
        self.foot_first_contact[env_ids] = False
        for component in self.components:
            component.reset(env_ids)

    def _update_kinematic_history(self) -> None:
        """Joint acceleration over the step and the feet's air / contact timers (Isaac Lab's
        contact-sensor semantics: ``first_contact`` when a foot lands after a swing)."""
        dt = self.step_dt_s
        joint_vel = self._state_t[:, self.layout.qvel][:, 6:].float()
        self._joint_acc = (joint_vel - self._last_joint_vel) / dt
        self._last_joint_vel = joint_vel
        lay = self.layout
        contact = self._sensor_t[:, list(lay.foot_touch)].float() > FOOT_CONTACT_THRESHOLD_N
        self.foot_first_contact = contact & (self.foot_air_time_s > 0)
        self.foot_last_air_time_s = torch.where(
            self.foot_first_contact, self.foot_air_time_s + dt, self.foot_last_air_time_s
        )
        self.foot_air_time_s = torch.where(contact, 0.0, self.foot_air_time_s + dt)
        self.foot_contact_time_s = torch.where(contact, self.foot_contact_time_s + dt, 0.0)

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

    def _read_state(self, terminated: torch.Tensor | None = None) -> EnvState:
        """Batch state as float32 tensors from the state and sensor rows."""
        lay = self.layout
        qpos = self._state_t[:, lay.qpos].float()
        qvel = self._state_t[:, lay.qvel].float()
        sens = self._sensor_t.float()
        quat = qpos[:, 3:7]
        lin_vel_w = qvel[:, 0:3]
        foot_pos = torch.stack([sens[:, lay.foot_pos[0]], sens[:, lay.foot_pos[1]]], dim=1)
        foot_vel = torch.stack([sens[:, lay.foot_vel[0]], sens[:, lay.foot_vel[1]]], dim=1)
        return EnvState(
            base_pos_w=qpos[:, 0:3],
            base_quat_w=quat,
            base_lin_vel_w=lin_vel_w,
            base_lin_vel_b=quat_rotate_inverse(quat, lin_vel_w),
            base_ang_vel_b=qvel[:, 3:6],
            projected_gravity_b=quat_rotate_inverse(quat, self._gravity_dir_w),
            joint_pos_rad=qpos[:, 7:],
            joint_vel_rps=qvel[:, 6:],
            joint_torque_nm=sens[:, lay.torque],
            foot_contact_force_n=sens[:, list(lay.foot_touch)],
            foot_pos_w=foot_pos,
            action=self.action,
            last_action=self.last_action,
            applied_wrench=self.applied_wrench,
            assist_bound=self.assist.bound[self.phase],
            episode_time_s=self.episode_length_buf.float() * self.step_dt_s,
            command=self.command,
            phase=self.phase,
            num_phases=self.num_phases,
            randomization_params=self.randomization_params,
            default_joint_pos_rad=self._stand_rad,
            effort_limit_nm=self._effort_nm,
            weight_n=self.weight_n,
            terminated=(
                terminated
                if terminated is not None
                else torch.zeros(self.num_envs, dtype=torch.bool)
            ),
            step_dt_s=self.step_dt_s,
            joint_acc_rps2=self._joint_acc,
            joint_pos_limits_rad=self._joint_limits,
            foot_vel_w=foot_vel,
            foot_air_time_s=self.foot_air_time_s,
            foot_contact_time_s=self.foot_contact_time_s,
            foot_last_air_time_s=self.foot_last_air_time_s,
            foot_first_contact=self.foot_first_contact,
            body_ground_contact=sens[:, lay.contact] > 0.5,
            contact_body_names=lay.contact_bodies,
        )

    def _group(
        self, name: str, group: ObsGroup, s: EnvState, cache: dict[int, torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(clean, noisy) values of a group: its terms (scaled) concatenated, and the same plus
        each term's uniform noise when the group is noisy (else the clean tensor itself).
        ``cache`` holds the terms already evaluated for this state (groups share terms)."""
        parts = []
        for term in group.terms:
            if id(term) not in cache:
                value = term(s)
                cache[id(term)] = value * term.scale if term.scale != 1.0 else value
            parts.append(cache[id(term)])
        clean = torch.cat(parts, dim=-1)
        if not group.noisy:
            return clean, clean
        if name not in self._noise_scale:
            widths = torch.tensor([p.shape[1] for p in parts])
            amplitude = [term.noise if self.cfg.noise else 0.0 for term in group.terms]
            self._noise_scale[name] = torch.repeat_interleave(
                torch.tensor(amplitude, dtype=torch.float32), widths
            )
        noise = 2 * torch.rand(clean.shape, generator=self.generator) - 1
        return clean, clean + noise * self._noise_scale[name]

    def observation_layout(self) -> dict[str, list[tuple[str, int, int]]]:
        """Per group: (term name, first column, width) in column order (``policy_clean`` has the
        policy layout; ``history`` is H policy rows, oldest first)."""
        s = self.env_state
        layout: dict[str, list[tuple[str, int, int]]] = {}
        for name in ("policy", "privileged", "critic"):
            group: ObsGroup = getattr(self.task.observations, name)
            col = 0
            layout[name] = []
            for term in group.terms:
                width = int(term(s).shape[1])
                layout[name].append((term.name, col, width))
                col += width
        layout["policy_clean"] = layout["policy"]
        return layout

    def observation_term(self, group: str, term: str) -> torch.Tensor:
        """The columns of one named term in the current observation group (N, D)."""
        for name, start, width in self.observation_layout()[group]:
            if name == term:
                return self._obs[group][:, start : start + width]
        raise KeyError(f"observation group '{group}' has no term '{term}'")

    def _observations(self, reset_ids: torch.Tensor, push_history: bool = True) -> TensorDict:
        """Build all observation groups from :attr:`env_state`; push the new policy observation
        into the history (a step) and fill the history of reset envs with it."""
        s = self.env_state
        groups = self.task.observations
        cache: dict[int, torch.Tensor] = {}
        clean, noisy = self._group("policy", groups.policy, s, cache)
        if self.history is None:
            self.history = HistoryBuffer(self.num_envs, self.cfg.history_length, clean.shape[1])
        if push_history:
            self.history.push(noisy)
        if reset_ids.numel():
            self.history.fill(reset_ids, noisy[reset_ids])
        return TensorDict(
            {
                "policy": noisy,
                "history": self.history.flat().clone(),
                "privileged": self._group("privileged", groups.privileged, s, cache)[1],
                "critic": self._group("critic", groups.critic, s, cache)[1],
                "base_lin_vel": s.base_lin_vel_b.clone(),
                "policy_clean": clean,
            },
            batch_size=[self.num_envs],
        )
