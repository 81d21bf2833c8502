"""``G1VecEnv``: N G1 instances stepped together, as an rsl-rl ``VecEnv``, assembled from parts.

Each part owns its state and ``state_dict`` (:data:`PARTS`): the physics (MuJoCo C or Warp,
:mod:`rl.envs.backends`), the motion and assist halves of the action (:mod:`rl.envs.assist_action`
states the wrench's frame), observation groups, pushes, randomiser, reset events, contact timers
and the task's components. :meth:`G1VecEnv.step` is the list of stages over the whole batch. The
env never branches on a task and knows no curriculum (Algorithm 1 is the runner's, through the
setters below).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rl.envs.assist import WRENCH_DIM
from rl.envs.assist_action import AssistAction
from rl.envs.backends import make_physics
from rl.envs.config import EnvConfig
from rl.envs.contact_timers import ContactTimers
from rl.envs.host_values import to_host
from rl.envs.model import build_physics_model
from rl.envs.motion_action import MotionAction, checked_actions
from rl.envs.observation_groups import ObservationGroups
from rl.envs.pushes import Pushes
from rl.envs.randomization import Randomizer
from rl.envs.reset_events import ResetEvents
from rl.envs.state import EnvState
from rl.envs.task_components import TaskComponents
from rl.envs.task_schema import TaskConfig
from rl.envs.terms import any_failure, sum_rewards
from robots import g1
from robots.mujoco_model import MujocoModelConfig

GRAVITY_MPS2 = 9.81
PARTS = ("physics", "motion", "assist", "observations", "pushes", "randomizer", "resets",
         "contacts", "task_components")  # fmt: skip
"""The env's parts, each with its own ``state_dict`` (keys of :meth:`G1VecEnv.state_dict`)."""


class G1VecEnv(VecEnv):
    """Batched G1 environment implementing ``rsl_rl.env.VecEnv`` (see ``docs/environments.md``).

    Actions (N, 35): [:, :29] motion action a (joint target = stand + ACTION_SCALE_RAD * a),
    [:, 29:] raw assist head output (:class:`rl.envs.assist_action.AssistAction`).
    """

    def __init__(
        self, cfg: EnvConfig, task: TaskConfig, model_cfg: MujocoModelConfig = MujocoModelConfig()
    ) -> None:
        # The physics' torch device (EnvConfig checks that MuJoCo C runs with "cpu"): every part
        # builds its tensors there and draws from one generator there, so a step on a GPU makes
        # no host <-> device copies of the robot's state (docs/gpu.md).
        self.cfg, self.task, self.device = cfg, task, cfg.device
        dev = self.device
        self.num_envs = n = cfg.num_envs
        self.num_actions = g1.NUM_JOINTS + WRENCH_DIM
        self.num_phases, self.phase_names = task.num_phases, task.phase_names
        self.generator = gen = torch.Generator(device=dev).manual_seed(cfg.seed)
        model_cfg = MujocoModelConfig(**{**model_cfg.__dict__, "floor": task.scene.floor})
        scene = task.scene
        self.model = build_physics_model(
            model_cfg, scene.link_collisions, scene.terrain, scene.tracked_bodies
        )
        self.total_mass_kg = float(self.model.body_subtreemass[0])
        self.weight_n = self.total_mass_kg * GRAVITY_MPS2
        self.randomizer = Randomizer(task.randomization, self.model, n, gen, dev)
        self.physics = make_physics(cfg, self.model, self.randomizer.models)
        self.layout, self.physics_dt_s = self.physics.layout, self.physics.physics_dt_s
        self.step_dt_s = dt = self.physics_dt_s * cfg.decimation
        self.max_episode_length = math.ceil(task.episode_length_s / dt)
        self.resets = ResetEvents(task.initial_state, n, self.max_episode_length, gen, dev)
        self.pushes = Pushes(task.pushes, n, dt, gen, dev)
        self.contacts = ContactTimers(n, dt, dev)
        self.observations = ObservationGroups(
            task.observations, n, cfg.history_length, cfg.noise, gen, dev
        )
        self.assist = AssistAction(
            task.default_assist_bound(), n, task.phase_names, task.less_assist_weight, gen, dev
        )
        self.motion = MotionAction(n, dev)
        self._constants = {  # the EnvState fields that never change
            "num_phases": self.num_phases,
            "default_joint_pos_rad": self.motion.stand_rad,
            "effort_limit_nm": torch.as_tensor(g1.EFFORT_LIMIT_NM, dtype=torch.float32, device=dev),
            "weight_n": self.weight_n,
            "step_dt_s": dt,
            "joint_pos_limits_rad": torch.as_tensor(self.layout.joint_range_rad).float().to(dev),
        }
        self.task_components = TaskComponents(task, n, self.max_episode_length, gen, dev)
        self.reset_envs(torch.arange(n, device=dev))

    state = property(lambda self: self.physics.state, doc="(N, nstate) MuJoCo state rows.")
    control = property(lambda self: self.physics.control, doc="(N, decimation, ncontrol) rows.")
    models = property(lambda self: self.physics.models, doc="(N,) the MjModel of each env.")
    physics_datas = property(lambda self: self.physics.physics_datas, doc="Rollout MjData.")
    num_threads = property(lambda self: self.physics.num_threads, doc="Physics threads.")
    diverged_total = property(lambda self: self.physics.diverged_total, doc="Rows replaced.")
    randomization_params = property(lambda self: self.randomizer.params, doc="(N, 5) domain.")
    applied_wrench = property(lambda self: self.assist.applied_wrench, doc="(N, 6) heading F.")
    assist_mask = property(lambda self: self.assist.mask, doc="(N, 6) this step's random mask.")
    command_gen = property(lambda self: self.task_components.command_gen, doc="The command.")
    phase_machine = property(lambda self: self.task_components.phase_machine, doc="Phases.")
    skill = property(lambda self: self.task_components.skill, doc="The skill measure.")
    components = property(lambda self: self.task_components.all, doc="The three above.")
    phase = property(lambda self: self.task_components.phase, doc="(N,) long task phase.")
    command = property(lambda self: self.task_components.command, doc="(N, C) task command.")

    @property
    def episode_length_buf(self) -> torch.Tensor:  # type: ignore[override]
        """(N,) long policy steps of each episode (runners may overwrite it)."""
        return self.resets.episode_length_buf

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        self.resets.episode_length_buf = value

    def for_evaluation(self) -> None:
        """The finished skill's setting, for an evaluation of the policy alone: each task
        component's (e.g. a command curriculum's full ranges) and the judged pushes."""
        for component in self.components:
            component.for_evaluation()
        self.pushes.for_evaluation()

    def set_assist_bound(self, eta: torch.Tensor) -> None:
        """Set eta (num_phases, 6) [N, Nm], the per-phase, per-axis wrench bound."""
        self.assist.set_bound(eta)

    def set_assist_enabled(self, enabled: bool) -> None:
        """Switch the assist wrench on or off (off: F = 0 whatever the head outputs)."""
        self.assist.set_enabled(enabled)

    def set_random_mask_prob(self, zeta: float) -> None:
        """Set zeta, the probability of dropping each wrench component every step."""
        self.assist.set_mask_prob(zeta)

    def set_less_assist_reward(self, enabled: bool) -> None:
        """Add (or stop adding) the less-assist reward exp(-2|F|/|eta|) to the task reward."""
        self.assist.set_less_assist_reward(enabled)

    def use_alone_envs(self, share: float, window: int) -> None:
        """Keep the first ``share`` of the envs without help, their skill measured in a window
        of ``window`` finished episodes of their own; ``share`` 0: no alone envs."""
        self.assist.set_alone_share(share)
        self.task_components.track_alone(window if share > 0 else None)

    def get_observations(self) -> TensorDict:
        """Current observation groups (see ``docs/environments.md``, "Observations")."""
        return self.observations.obs

    def joint_targets_to_actions(self, joint_pos_rad: torch.Tensor) -> torch.Tensor:
        """The motion actions (N, 29) whose PD targets are ``joint_pos_rad`` (N, 29) [rad]."""
        return self.motion.to_actions(joint_pos_rad, self._action_base())

    def reset_envs(self, env_ids: torch.Tensor) -> TensorDict:
        """Start new episodes for ``env_ids`` (M,) now: the task's initial-state distribution,
        fresh randomisation, components reset; the observations are rebuilt and returned. Other
        envs keep their state and history (their observations get fresh noise)."""
        env_ids = torch.as_tensor(env_ids, dtype=torch.long, device=self.device)
        self._reset(env_ids)
        self.env_state = self._read_state()
        self.task_components.update(self.env_state, 0.0)
        self.env_state = self._read_state()
        return self.observations.compute(self.env_state, env_ids, stepped=False)

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Apply actions (N, 35) for one policy step; returns (obs, rewards, dones, extras)."""
        nonfinite_actions = self._apply_actions(actions)
        self.pushes.apply(self.physics)
        diverged = self.physics.step()
        self.resets.advance()
        robot = self.physics.read()
        self.contacts.update(robot["joint_vel_rps"].clone(), robot["foot_contact_force_n"])
        state = self.env_state = self._read_state(robot=robot)
        failed, termination_log = any_failure(self.task.terminations, state)
        state.terminated = failed
        terminated = failed | diverged
        ends = self.task_components.time_outs() & ~terminated  # the command's, not a failure
        time_outs = self.resets.time_outs(terminated) | ends
        dones = terminated | time_outs
        dt = self.step_dt_s
        reward, log = sum_rewards(self.task.rewards, state, dt, self.assist.rewards(dt))
        reward = torch.where(diverged, torch.zeros_like(reward), torch.nan_to_num(reward))
        log.update(termination_log)
        log["Episode/diverged_envs"] = diverged.sum()
        log["Episode/diverged_envs_total"] = self.physics.diverged_counter
        log["Episode/nonfinite_action_envs"] = nonfinite_actions
        log["Episode/terminated"] = terminated.float().mean()
        log.update(self.assist.log())
        log["Train/mean_step_reward"] = reward.mean()
        faults = self.physics.fault_flags()  # keys without a "/": never a log key
        log, done_ids = to_host({**log, **faults}, dones)  # the step's one wait for the device
        self.physics.raise_on_faults({k: log.pop(k) for k in faults})
        self.motion.end_step()
        if done_ids.numel():
            lived = self.resets.lived_steps[done_ids]
            self.task_components.on_episodes_end(
                done_ids, time_outs[done_ids], lived, state, self.assist.alone
            )
            self._reset(done_ids)
            state = self._read_state(terminated=failed)
        self._advance_task(state)
        obs = self.observations.compute(state, done_ids, stepped=True)
        progress = log["Episode/skill_progress"] = self.skill.progress()
        alone = self.task_components.alone_skill
        alone_progress = {} if alone is None else {"skill_progress_alone": alone.progress()}
        log.update({f"Episode/{k}": v for k, v in alone_progress.items()})
        log.update(self.task_components.log())
        extras = {"time_outs": time_outs, "log": log, "assist": self.assist.step_extras,
                  "skill_progress": progress, **alone_progress}  # fmt: skip
        return obs, reward, dones, extras

    def close(self) -> None:
        """Stop the physics."""
        self.physics.close()

    def state_dict(self) -> dict[str, Any]:
        """Everything that evolves while stepping, part by part (:data:`PARTS`), plus the RNG
        stream. With :meth:`load_state_dict` a resumed run continues bit for bit (on CPU)."""
        state = {name: getattr(self, name).state_dict() for name in PARTS}
        return {**state, "generator": self.generator.get_state()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output of an env of the same task, size and config."""
        for name in PARTS:
            getattr(self, name).load_state_dict(state[name])
        self.generator.set_state(state["generator"])
        self.env_state = self._read_state()

    def observation_layout(self) -> dict[str, list[tuple[str, int, int]]]:
        """Per group: (term name, first column, width) in column order (``policy_clean`` has the
        policy layout; ``history`` is H policy rows, oldest first)."""
        return self.observations.layout(self.env_state)

    def observation_term(self, group: str, term: str) -> torch.Tensor:
        """The columns of one named term in the current observation group (N, D)."""
        return self.observations.term(self.env_state, group, term)

    def _apply_actions(self, actions: torch.Tensor) -> int:
        """Check the actions (N, 35), zero non-finite rows (MuJoCo would reset them; returned: how
        many), clip, and hand the joint targets and the world-frame assist wrench to the physics."""
        shape = (self.num_envs, self.num_actions)
        actions, nonfinite = checked_actions(actions, shape, self.cfg.clip_actions, self.device)
        targets = self.motion.apply(actions[:, : g1.NUM_JOINTS], self._action_base())
        self.assist.apply(actions[:, g1.NUM_JOINTS :], self.phase)
        self.physics.set_controls(targets, self.assist.to_world(self.physics.qpos[:, 3:7].float()))
        return nonfinite

    def _action_base(self) -> torch.Tensor | None:
        """The pose (N, 29) [rad] the joint actions are relative to this step: the command's
        reference joints where the task asks for it, else ``None`` (the standing pose)."""
        if not self.task.actions_around_reference:
            return None
        base = self.command_gen.reference_joint_pos_rad()
        if self.task.action_feedforward:
            base = base + self.motion.feedforward_rad(
                *self.command_gen.reference_joint_feedforward()
            )
        return base

    def _advance_task(self, state: EnvState) -> None:
        """Phase and command from the state after the step (and resets); ``state`` gets them, the
        new phase's bound and the actions: it is what the next observations show."""
        self.task_components.update(state, self.step_dt_s)
        state.phase, state.command = self.phase, self.command
        state.targets = self.task_components.targets
        state.assist_bound = self.assist.observed_bound(self.phase)
        state.action, state.last_action = self.motion.action, self.motion.last_action
        self.env_state = state

    def _reset(self, env_ids: torch.Tensor) -> None:
        """Put ``env_ids`` (M,) back to a state of the task's initial-state distribution, with
        fresh randomisation, every part and component reset (in the order of their draws)."""
        qpos, qvel = self.resets.initial_state(env_ids, self.physics, self.components)
        self.randomizer.reset(env_ids)
        self.physics.reset_rows(env_ids, qpos, qvel)
        self.resets.restart(env_ids)
        self.motion.reset(env_ids)
        self.assist.reset(env_ids)
        self.pushes.reset(env_ids)
        self.contacts.reset(env_ids, self.physics.qvel[env_ids][:, 6:].float())
        self.task_components.reset(env_ids)

    def _read_state(
        self, terminated: torch.Tensor | None = None, robot: dict[str, Any] | None = None
    ) -> EnvState:
        """Batch state as float32 tensors: the physics' reading (``robot``, read now if None)
        and the env's own buffers."""
        if terminated is None:
            terminated = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        return EnvState(
            **(robot if robot is not None else self.physics.read()),
            **self.contacts.fields(),
            **self._constants,
            action=self.motion.action,
            last_action=self.motion.last_action,
            applied_wrench=self.assist.applied_wrench,
            assist_bound=self.assist.observed_bound(self.phase),
            episode_time_s=self.resets.episode_length_buf.float() * self.step_dt_s,
            command=self.command,
            phase=self.phase,
            randomization_params=self.randomizer.params,
            terminated=terminated,
            targets=self.task_components.targets,
        )
