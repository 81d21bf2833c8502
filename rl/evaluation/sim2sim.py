"""Sim-to-sim evaluation: the exported policy, assistance off, in a second MuJoCo set-up built
independently of the training physics, driven only through the deployment bundle (``policy.json``).

What differs from the training physics (``rl.envs``), on purpose, as a second simulator would:

============================ ======================================== ===========================
                             training env                             sim2sim
============================ ======================================== ===========================
physics step, decimation     5 ms x 4 (50 Hz policy)                  1 ms x 20 (the paper's)
collision geometry           sole spheres + fitted link primitives    sole spheres + the URDF's
                                                                      collision meshes
contact solver               pyramidal cone, default impedance        elliptic cone, impratio 10
integrator                   implicitfast                             Euler
actuation                    MuJoCo position actuators (implicit PD)  explicit PD torque at 1 kHz
                                                                      from the bundle's gains,
                                                                      clipped to effort limits
observation                  the env's terms                          rebuilt from the bundle's
                                                                      description (robot-side)
============================ ======================================== ===========================

Like the training physics' evaluation, each robot has its own draw of the task's domain
randomisation (friction, payload, CoM offset: its own ``MjModel`` copy) and its policy terms' own
uniform observation noise, from sim2sim's generators (``Sim2SimConfig.randomize``). So a task whose
robots all start on one frame (a tracking reference) still gets N different rollouts, not one
rollout N times; a ``quiet`` task has neither.

What is shared with training, on purpose, is the task's logic: its command generator and phase
machine (``task.commands``, ``task.phases``) are built from the task config and driven in the
training env's order (:class:`TaskLogic`), in their evaluation setting (``for_evaluation``: e.g. the
walk's full command ranges), from their own generator seeded with ``Sim2SimConfig.seed``. So the
walk's velocity command and gait clock, the dance's clip reference (each robot starts on its clip
frame) and the backflip's start signal and phase FSM reach the policy through the bundle's
``command`` columns as in training. The scene is the plane: a task's terrain is not rebuilt (walk
runs on flat ground here), and the skill measure (e.g. walk's terrain levels) is not used.

The task's own termination and reward terms score the rollouts (same metrics as ``eval``) on an
:class:`EnvState` of the sim2sim robots (feet, link-ground contacts, joint accelerations, foot
timers, episode time, command, phase; no wrench), and the task's pushes are applied as in training
(same interval and size, own generator), so the two columns compare like with like. Where the
task's evaluation reads no more than the sim2sim robots have (``in_sim2sim``: the tracking, walk and
flip judges), it scores the rollouts too (``task_metrics``: flips landed, turn, tracking errors,
velocity errors per command).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from rl.agents.export import OnnxMotionPolicy
from rl.envs.contact_timers import ContactTimers
from rl.envs.model import contact_bodies
from rl.envs.randomization import ModelRandomizer, nominal_params, sample_params
from rl.envs.state import EnvState, quat_rotate_inverse
from rl.envs.task_schema import TaskConfig
from rl.envs.vec_env import GRAVITY_MPS2
from rl.runs.folder import (
    POLICY_BUNDLE_FILE,
    REEXPORT_ADVICE,
    DamagedRunFileError,
    read_run_json,
)
from robots import g1
from robots.mujoco_model import FLOOR_GEOM, STAND_KEYFRAME, MujocoModelConfig, build_mujoco_spec


@dataclass(frozen=True)
class Sim2SimConfig:
    """The second simulator's settings and the rollout size."""

    num_envs: int = 8  # independent robots (one MjData each) [-]
    physics_dt_s: float = 0.001  # physics step [s]
    impratio: float = 10.0  # frictional-to-normal impedance ratio of the elliptic cone [-]
    joint_pos_noise_rad: float = 0.05  # uniform +- initial joint offset from the default pose [rad]
    seed: int = 1  # seed of the initial states and of the task's command and phase draws [-]
    randomize: bool = True  # the task's randomisation ranges and observation noise, own draws
    # Each setting below can be set to the training physics' to find where a gap comes from
    # (docs/results/backflip_track/sim2sim_gap.py); the defaults are the second simulator's.
    cone: str = "elliptic"  # friction cone: "elliptic" or "pyramidal" (training's)
    integrator: str = "euler"  # "euler" or "implicitfast" (training's)
    link_meshes: bool = True  # the URDF's collision meshes; False: training's link primitives
    links_off_floor: tuple[str, ...] = ()  # links whose collision geometry skips the floor

    def __post_init__(self) -> None:
        if self.num_envs < 1 or self.physics_dt_s <= 0:
            raise ValueError("sim2sim needs num_envs >= 1 and a positive physics step")
        for name, options in (("cone", CONES), ("integrator", INTEGRATORS)):
            if getattr(self, name) not in options:
                raise ValueError(
                    f"sim2sim {name} {getattr(self, name)!r} is not one of {sorted(options)}"
                )


CONES = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}
INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
}


def build_sim2sim_model(cfg: Sim2SimConfig) -> mujoco.MjModel:
    """The G1 with its URDF collision meshes on the floor (or, ``link_meshes`` off, the training
    env's link primitives), no actuators (torques are explicit)."""
    spec = build_mujoco_spec(
        MujocoModelConfig(timestep_s=cfg.physics_dt_s, body_floor_collision=True, actuators=False)
    )
    if not cfg.link_meshes:
        from robots.collision_primitives import (
            add_link_primitives,
            fit_link_primitives,
            remove_meshes,
        )

        add_link_primitives(remove_meshes(spec), fit_link_primitives())
    for name in cfg.links_off_floor:
        body = spec.body(name)
        if body is None:
            raise ValueError(f"sim2sim links_off_floor: '{name}' is not a link of the G1")
        for geom in body.geoms:
            if geom.contype == 2:  # a link's collision geometry (the soles are 1)
                geom.contype = 0
    spec.option.cone = CONES[cfg.cone]
    spec.option.impratio = cfg.impratio
    spec.option.integrator = INTEGRATORS[cfg.integrator]
    return spec.compile()


def bundle_observation(
    bundle: dict, gyro, quat_wxyz, q, qdot, last_action, command=None, base_lin_vel_b=None
) -> np.ndarray:
    """One robot's policy observation from raw signals, as the bundle describes it; ``command``
    (C,) is the task command (what a robot's joystick, gait clock or clip player produces, see the
    command term's ``parts``), needed when the bundle has a command term; ``base_lin_vel_b`` (3,)
    [m/s] the pelvis velocity in the pelvis frame (a state estimator's output on a robot), needed
    when the bundle has a ``base_lin_vel`` term."""
    w, x, y, z = quat_wxyz
    gravity_b = (
        np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]) * -1.0
    )  # R^T (0, 0, -1): minus the third row of R
    default = np.array([j["default_pos_rad"] for j in bundle["joints"]])
    signals = {
        "base_ang_vel": gyro,
        "projected_gravity": gravity_b,
        "joint_pos": q - default,
        "joint_vel": qdot,
        "last_action": last_action,
        "command": command,
        "base_lin_vel": base_lin_vel_b,
    }
    obs = np.zeros(bundle["observation"]["width"])
    for term in bundle["observation"]["terms"]:
        if term["name"] not in signals:
            raise ValueError(f"sim2sim cannot compute observation term '{term['name']}' yet")
        start, stop = term["columns"]
        if signals[term["name"]] is None:
            signal = "command" if term["name"] == "command" else "base_lin_vel_b"
            raise ValueError(
                f"the policy reads '{term['name']}' (columns {start}:{stop}): pass `{signal}`"
            )
        obs[start:stop] = term["scale"] * signals[term["name"]]
    return obs


def observation_noise(bundle: dict, task: TaskConfig) -> np.ndarray:
    """Half-widths (P,) of the uniform noise the training env adds to each column of the policy
    observation: each bundle term's noise in the task's policy group, zero where the group is
    not noisy (a ``quiet`` task) or the bundle has a term the task does not."""
    width = bundle["observation"]["width"]
    group = task.observations.policy
    if not group.noisy:
        return np.zeros(width)
    amplitude = {term.name: term.noise for term in group.terms}
    out = np.zeros(width)
    for term in bundle["observation"]["terms"]:
        start, stop = term["columns"]
        out[start:stop] = amplitude.get(term["name"], 0.0)
    return out


def _lin_vel_b(data: mujoco.MjData) -> np.ndarray:
    """The free joint's linear velocity (world frame in ``qvel``) in the pelvis frame (3,) [m/s]."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, data.qpos[3:7])
    return rot.reshape(3, 3).T @ data.qvel[:3]


class TaskLogic:
    """A task's command generator and phase machine for N robots outside the training env, driven
    in the order :class:`rl.envs.vec_env.G1VecEnv` drives them.

    At the start: the task's initial-state hook, each part's ``reset_state`` (which may move the
    robot, e.g. the dance onto its clip frame), each part's ``reset``; then :meth:`advance` with
    ``dt_s`` 0. After every policy step: :meth:`advance` with the policy step. Both parts are in
    their evaluation setting (``for_evaluation``) and draw from one generator seeded with ``seed``.
    """

    def __init__(self, task: TaskConfig, num_envs: int, seed: int) -> None:
        self.task = task
        self.generator = torch.Generator().manual_seed(seed)
        self.command_gen = task.commands.build(num_envs, self.generator)
        self.phase_machine = task.phases.build(num_envs, self.generator)
        self.parts = (self.command_gen, self.phase_machine)
        for part in self.parts:
            part.for_evaluation()
        self.command = torch.zeros(num_envs, task.commands.dim)  # (N, C) the policy's next input
        self.phase = torch.zeros(num_envs, dtype=torch.long)  # (N,) phase of the next step

    def reset(self, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Start every robot's episode; the float64 MuJoCo initial states ``qpos`` (N, 36) and
        ``qvel`` (N, 35) are edited in place by the task's hooks."""
        env_ids = torch.arange(qpos.shape[0])
        hook = self.task.initial_state.reset_state
        if hook is not None:
            hook(env_ids, qpos, qvel, self.generator)
        for part in self.parts:
            part.reset_state(env_ids, qpos, qvel, self.generator)
        for part in self.parts:
            part.reset(env_ids)

    def advance(self, state: EnvState, dt_s: float) -> None:
        """Phase and command of the next step from ``state``, the robots after a step of ``dt_s``
        [s] (0: the initial state)."""
        self.phase = self.phase_machine.update(state)
        self.command = self.command_gen.compute(state, dt_s)


class _EvaluatedEnv:
    """What a task's evaluator reads of the training env (:class:`G1VecEnv`'s names), for the
    sim2sim robots: their latest :class:`EnvState` and the task's logic. Used for evaluations
    that say they need no more (``in_sim2sim``: the tracking, flip and walk judges)."""

    device = "cpu"
    skill = None  # no skill measure here (walk's terrain levels): the scene is the plane

    def __init__(self, task: TaskConfig, logic: TaskLogic, state: EnvState) -> None:
        self.task, self.logic, self.env_state = task, logic, state
        self.num_envs, self.step_dt_s = state.joint_pos_rad.shape[0], state.step_dt_s
        self.command_gen = logic.command_gen
        self.task_components = self  # the env's parts: the command's targets below

    def reset_envs(self, env_ids: torch.Tensor) -> None:
        """Nothing to do: each robot's one episode starts from its initial state already."""

    phase = property(lambda self: self.logic.phase, doc="(N,) phase of the next step.")
    targets = property(lambda self: self.logic.command_gen.targets(), doc="The next targets.")


class _Robots:
    """The sim2sim robots (one ``MjData`` each) and what their :class:`EnvState` needs beyond it:
    joint accelerations over the step and the feet's air / contact timers (the training env's
    :class:`ContactTimers`), the link-ground contacts of the training env's contact bodies."""

    def __init__(
        self,
        model: mujoco.MjModel,
        qpos: np.ndarray,
        qvel: np.ndarray,
        step_dt_s: float,
        params: torch.Tensor | None = None,
        payload_body: str = "torso_link",
    ) -> None:
        """Robots at ``qpos`` (N, 36), ``qvel`` (N, 35), stepped every ``step_dt_s`` [s];
        ``params`` (N, 5): each robot's randomisation row (its own copy of ``model``, the
        payload on ``payload_body``), None: all step with the nominal ``model``."""
        self.model = model
        n = self.num_envs = qpos.shape[0]
        if params is None:
            self.models = [model] * n
            self._randomization = nominal_params(n, model)
        else:
            writer = ModelRandomizer.for_model(model, payload_body)
            self.models = [copy.copy(model) for _ in range(n)]
            for own, row in zip(self.models, params.numpy(), strict=True):
                writer.apply(own, row)
            self._randomization = params.float()
        self.datas = []
        for own, q, v in zip(self.models, qpos, qvel, strict=True):
            data = mujoco.MjData(own)
            data.qpos[:], data.qvel[:] = q, v
            mujoco.mj_forward(own, data)
            self.datas.append(data)
        self.contact_body_names = contact_bodies(model)
        self._body_column = np.full(model.nbody, -1)
        for col, name in enumerate(self.contact_body_names):
            self._body_column[model.body(name).id] = col
        self._floor = model.geom(FLOOR_GEOM).id
        self._touch = [int(model.sensor(f"{s}_touch").adr[0]) for s in g1.SOLE_FRAMES]
        self._soles = [model.site(s).id for s in g1.SOLE_FRAMES]
        limits = np.array([model.joint(j.name).range for j in g1.JOINTS])
        self._joint_limits = torch.tensor(limits).float()
        self.weight_n = float(model.body_subtreemass[0]) * GRAVITY_MPS2
        self.step_dt_s = step_dt_s
        self.contacts = ContactTimers(n, step_dt_s)
        self.contacts.reset(torch.arange(n), self._stack("qvel")[:, 6:])

    def _stack(self, field: str) -> torch.Tensor:
        return torch.tensor(np.stack([getattr(d, field) for d in self.datas])).float()

    def _foot_contact_n(self) -> torch.Tensor:
        return torch.tensor([[d.sensordata[a] for a in self._touch] for d in self.datas]).float()

    def _foot_vel_w(self, data: mujoco.MjData) -> np.ndarray:
        vel = np.zeros((2, 6))  # (angular, linear) of each sole site, world orientation
        for k, site in enumerate(self._soles):
            mujoco.mj_objectVelocity(self.model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel[k], 0)
        return vel[:, 3:]

    def _ground_contacts(self, data: mujoco.MjData) -> np.ndarray:
        flags = np.zeros(len(self.contact_body_names), dtype=bool)
        geom = np.asarray(data.contact.geom).reshape(-1, 2)
        on_floor = geom == self._floor
        other = np.where(on_floor[:, 0], geom[:, 1], geom[:, 0])[on_floor.any(axis=1)]
        cols = self._body_column[self.model.geom_bodyid[other]]
        flags[cols[cols >= 0]] = True
        return flags

    def after_step(self) -> None:
        """Advance the joint accelerations and foot timers over the policy step just taken."""
        self.contacts.update(self._stack("qvel")[:, 6:], self._foot_contact_n())

    def state(self, logic: TaskLogic, tau, action, last_action, time_s: float) -> EnvState:
        """The batch EnvState (assistance off) for the task's terms and logic: ``tau`` (N, 29)
        [Nm] of the last physics step, motion actions of this and the previous step (N, 29),
        episode time ``time_s`` [s]."""
        qpos, qvel = self._stack("qpos"), self._stack("qvel")
        n = self.num_envs
        quat = qpos[:, 3:7]
        feet = np.stack([[d.site_xpos[i] for i in self._soles] for d in self.datas])
        zeros6 = torch.zeros(n, 6)
        return EnvState(
            base_pos_w=qpos[:, :3], base_quat_w=quat, base_lin_vel_w=qvel[:, :3],
            base_lin_vel_b=quat_rotate_inverse(quat, qvel[:, :3]), base_ang_vel_b=qvel[:, 3:6],
            projected_gravity_b=quat_rotate_inverse(quat, torch.tensor([0.0, 0, -1]).expand(n, 3)),
            joint_pos_rad=qpos[:, 7:], joint_vel_rps=qvel[:, 6:],
            joint_torque_nm=torch.tensor(tau).float(), foot_contact_force_n=self._foot_contact_n(),
            foot_pos_w=torch.tensor(feet).float(),
            action=torch.tensor(action).float(), last_action=torch.tensor(last_action).float(),
            applied_wrench=zeros6, assist_bound=zeros6, episode_time_s=torch.full((n,), time_s),
            command=logic.command, phase=logic.phase, num_phases=logic.task.num_phases,
            randomization_params=self._randomization,
            default_joint_pos_rad=torch.tensor(g1.STAND_JOINT_POS_RAD).float(),
            effort_limit_nm=torch.tensor(g1.EFFORT_LIMIT_NM).float(), weight_n=self.weight_n,
            terminated=torch.zeros(n, dtype=torch.bool), step_dt_s=self.step_dt_s,
            joint_pos_limits_rad=self._joint_limits,
            foot_vel_w=torch.tensor(np.stack([self._foot_vel_w(d) for d in self.datas])).float(),
            **self.contacts.fields(),
            body_ground_contact=torch.from_numpy(
                np.stack([self._ground_contacts(d) for d in self.datas])
            ),
            contact_body_names=self.contact_body_names,
            **self._tracked_bodies(logic.task.scene.tracked_bodies),
            targets=logic.command_gen.targets(),
        )  # fmt: skip

    def _tracked_bodies(self, bodies: tuple[str, ...]) -> dict[str, torch.Tensor]:
        """The ``EnvState.body_*`` fields of a tracking task's links (link frames, world)."""
        ids = [self.model.body(b).id for b in bodies]
        vel = np.zeros((self.num_envs, len(ids), 6))
        for i, data in enumerate(self.datas):
            for k, body in enumerate(ids):
                mujoco.mj_objectVelocity(
                    self.model, data, mujoco.mjtObj.mjOBJ_XBODY, body, vel[i, k], 0
                )
        pose = {
            attr: np.stack([getattr(d, attr)[ids] for d in self.datas])
            for attr in ("xpos", "xquat")
        }
        return {
            "body_pos_w": torch.tensor(pose["xpos"]).float(),
            "body_quat_w": torch.tensor(pose["xquat"]).float(),
            "body_lin_vel_w": torch.tensor(vel[..., 3:]).float(),
            "body_ang_vel_w": torch.tensor(vel[..., :3]).float(),
        }


def _initial_states(
    model: mujoco.MjModel, task: TaskConfig, logic: TaskLogic, cfg: Sim2SimConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Initial ``qpos`` (N, 36) and ``qvel`` (N, 35): the standing keyframe with uniform joint
    noise, a random heading when the task draws one, then the task's logic (:meth:`TaskLogic.reset`,
    e.g. the dance's clip frame)."""
    rng = np.random.default_rng(cfg.seed)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    n = cfg.num_envs
    qpos, qvel = np.tile(data.qpos, (n, 1)), np.zeros((n, model.nv))
    for q in qpos:
        q[7:] += rng.uniform(-1, 1, g1.NUM_JOINTS) * cfg.joint_pos_noise_rad
        if task.initial_state.random_yaw:
            yaw = rng.uniform(-math.pi, math.pi)
            q[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    logic.reset(torch.from_numpy(qpos), torch.from_numpy(qvel))  # views: edited in place
    return qpos, qvel


BUNDLE_KEYS = (
    "onnx",
    "clip_actions",
    "control.policy_rate_hz",
    "observation.width",
    "observation.history_length",
    "observation.terms",
    "joints",
)
"""The keys of ``policy.json`` that sim2sim reads (dotted: nested)."""
BUNDLE_JOINT_KEYS = ("kp", "kd", "effort_limit_nm", "default_pos_rad", "action_scale_rad")
"""The keys sim2sim reads of each entry of the bundle's ``joints``."""
BUNDLE_TERM_KEYS = ("name", "columns")
"""The keys sim2sim reads of each entry of the bundle's ``observation.terms``."""


def _missing_bundle_key(bundle: dict[str, Any]) -> str:
    """The first key sim2sim reads that ``bundle`` lacks (dotted, ``joints[3].kp`` for an entry
    of a list); empty when none is missing."""
    for dotted in BUNDLE_KEYS:
        node: Any = bundle
        for depth, key in enumerate(dotted.split(".")):
            if not isinstance(node, dict) or key not in node:
                return ".".join(dotted.split(".")[: depth + 1])
            node = node[key]
    for where, entries, keys in (
        ("joints", bundle["joints"], BUNDLE_JOINT_KEYS),
        ("observation.terms", bundle["observation"]["terms"], BUNDLE_TERM_KEYS),
    ):
        if not isinstance(entries, list):
            return f"{where}[0]"
        for i, entry in enumerate(entries):
            for key in keys:
                if not isinstance(entry, dict) or key not in entry:
                    return f"{where}[{i}].{key}"
    return ""


def load_bundle(run_dir: Path, task: TaskConfig) -> dict[str, Any]:
    """The deployment bundle of ``run_dir``, checked against ``task``'s command width."""
    path = run_dir / POLICY_BUNDLE_FILE
    bundle = read_run_json(path, "the deployment bundle", REEXPORT_ADVICE.format(run_dir=run_dir))
    advice = REEXPORT_ADVICE.format(run_dir=run_dir)
    if not isinstance(bundle, dict):
        raise DamagedRunFileError(f"{path} is not a deployment bundle: {advice}")
    if "joints" not in bundle:
        raise DamagedRunFileError(
            f"{path} has no 'joints' (no deployment bundle: exported before format 2?): {advice}"
        )
    missing = _missing_bundle_key(bundle)
    if missing:
        raise DamagedRunFileError(f"{path} (the deployment bundle) has no '{missing}': {advice}")
    columns = {t["name"]: t["columns"] for t in bundle["observation"]["terms"]}
    width = columns["command"][1] - columns["command"][0] if "command" in columns else 0
    if width != task.commands.dim:
        raise ValueError(
            f"{path}: the policy reads a command of width {width}, task '{task.name}' makes one of "
            f"width {task.commands.dim}: evaluate the run with the task (and overrides) it was "
            "trained on"
        )
    return bundle


class _Pushes:
    """The task's velocity kicks (as the training env's): a timer per robot drawn from the push
    interval; when it runs out, a uniform horizontal base velocity change of at most
    ``velocity_xy_mps`` per axis. Own generator (seed + 1): the command draws stay the training
    env's."""

    def __init__(self, cfg, num_envs: int, seed: int) -> None:
        self.cfg = cfg
        self.rng = np.random.default_rng(seed + 1)
        self.timer_s = self._intervals(num_envs)

    def _intervals(self, m: int) -> np.ndarray:
        low, high = self.cfg.interval_range_s
        return low + (high - low) * self.rng.random(m)

    def kicks(self, dt_s: float) -> np.ndarray:
        """(N, 2) base velocity changes [m/s] for this policy step (zero for most robots)."""
        out = np.zeros((self.timer_s.shape[0], 2))
        if not self.cfg.enabled:
            return out
        self.timer_s -= dt_s
        due = np.flatnonzero(self.timer_s <= 0)
        v = self.cfg.velocity_xy_mps
        out[due] = (2 * self.rng.random((due.size, 2)) - 1) * v
        self.timer_s[due] = self._intervals(due.size)
        return out


def run_sim2sim(
    run_dir: str | Path,
    task: TaskConfig,
    num_steps: int,
    cfg: Sim2SimConfig = Sim2SimConfig(),
    on_step: Callable[[np.ndarray], None] | None = None,
) -> dict[str, Any]:
    """Roll the exported policy of ``run_dir`` out in the second simulator, the task's command and
    phases driven by :class:`TaskLogic`; survival and return of each robot's one episode.
    ``on_step(obs)`` sees the policy's observation (N, P) of every step before it acts."""
    run_dir = Path(run_dir)
    bundle = load_bundle(run_dir, task)
    policy = OnnxMotionPolicy(run_dir / bundle["onnx"])
    model = build_sim2sim_model(cfg)
    step_s = 1.0 / bundle["control"]["policy_rate_hz"]
    decimation = round(step_s / cfg.physics_dt_s)
    dt = decimation * cfg.physics_dt_s
    if decimation < 1 or abs(dt - step_s) > 1e-9:
        raise ValueError(
            f"sim2sim physics_dt_s {cfg.physics_dt_s} s must divide the policy step {step_s} s"
        )
    joints = bundle["joints"]
    kp, kd = np.array([j["kp"] for j in joints]), np.array([j["kd"] for j in joints])
    effort = np.array([j["effort_limit_nm"] for j in joints])
    default = np.array([j["default_pos_rad"] for j in joints])
    scale = np.array([j["action_scale_rad"] for j in joints])
    base_cols = bundle["control"].get("action_base_command_columns")
    feedforward = bundle["control"].get("action_feedforward")
    if feedforward is not None:  # (F, 29) planned torques, read once
        ff_torque_nm = np.asarray(feedforward["joint_torque_nm"], dtype=np.float64)
    h = bundle["observation"]["history_length"]
    n = cfg.num_envs
    logic = TaskLogic(task, n, cfg.seed)
    qpos0, qvel0 = _initial_states(model, task, logic, cfg)
    draws = torch.Generator().manual_seed(cfg.seed + 2)  # the command's draws stay training's
    params = (
        sample_params(n, task.randomization, draws)
        if cfg.randomize and task.randomization.enabled
        else None
    )
    robots = _Robots(model, qpos0, qvel0, dt, params, task.randomization.payload_body)
    noise = observation_noise(bundle, task) if cfg.randomize else np.zeros(0)
    noise_rng = np.random.default_rng(cfg.seed + 3)
    datas = robots.datas
    last_action = np.zeros((n, 29))
    tau = np.zeros((n, 29))
    start = robots.state(logic, tau, last_action, last_action, 0.0)
    logic.advance(start, 0.0)
    pushes = _Pushes(task.pushes, n, cfg.seed)
    judged = task.evaluation is not None and getattr(task.evaluation, "in_sim2sim", False)
    view = _EvaluatedEnv(task, logic, start)
    evaluator = task.evaluation.build(view) if judged else None
    history = [None] * n
    active = np.ones(n, dtype=bool)
    fell = np.zeros(n, dtype=bool)
    returns = np.zeros(n)
    lengths = np.zeros(n)
    for step in range(num_steps):
        command = logic.command.numpy()
        obs = np.stack([
            bundle_observation(bundle, d.qvel[3:6], d.qpos[3:7], d.qpos[7:], d.qvel[6:],
                               last_action[i], command[i], _lin_vel_b(d))
            for i, d in enumerate(datas)
        ])  # fmt: skip
        if noise.any():
            obs = obs + (2 * noise_rng.random(obs.shape) - 1) * noise
        if on_step is not None:
            on_step(obs)
        for i in range(n):
            history[i] = [obs[i]] * h if history[i] is None else history[i][1:] + [obs[i]]
        hist = np.stack([np.concatenate(hh) for hh in history]).astype(np.float32)
        action = np.clip(
            policy(obs.astype(np.float32), hist), -bundle["clip_actions"], bundle["clip_actions"]
        )
        target = default if base_cols is None else command[:, base_cols[0] : base_cols[1]]
        if feedforward is not None:  # the bundle's table, at the frame the command shows
            a, b = feedforward["joint_vel_command_columns"]
            torque = ff_torque_nm[logic.command_gen.frame(ahead=1).numpy()]
            target = target + kd / kp * command[:, a:b] + torque / kp
        target = target + scale * action
        kicks = pushes.kicks(dt)
        for i, data in enumerate(datas):
            if not active[i]:
                continue
            data.qvel[0:2] += kicks[i]
            for _ in range(decimation):
                tau[i] = np.clip(
                    kp * (target[i] - data.qpos[7:]) - kd * data.qvel[6:], -effort, effort
                )
                data.qfrc_applied[6:] = tau[i]
                mujoco.mj_step(robots.models[i], data)
        robots.after_step()
        state = robots.state(logic, tau, action, last_action, (step + 1) * dt)
        per_term = [t(state) for t in task.terminations]
        failed = torch.stack(per_term).any(dim=0) if per_term else torch.zeros(n, dtype=torch.bool)
        state.terminated = failed
        failed = failed.numpy()
        reward = sum(t(state) * (t.weight * dt) for t in task.rewards).numpy()
        returns += np.where(active, reward, 0.0)
        lengths += active
        fell |= active & failed
        was_active = active.copy()
        active &= ~failed
        ends = logic.command_gen.time_outs()  # a tracking reference's last frame: survived
        ends = np.zeros(n, dtype=bool) if ends is None else ends.numpy()
        active &= ~ends
        logic.advance(state, dt)
        if evaluator is not None:  # as rollout_alone calls it: after the step, next targets set
            view.env_state = state
            evaluator.on_step(
                view, torch.from_numpy(was_active), torch.from_numpy(failed | ends),
                {"time_outs": torch.from_numpy(ends & ~failed)},
            )  # fmt: skip
        last_action = action
        if not active.any():
            break
    metrics = {}
    if evaluator is not None:
        import tempfile

        from rl.evaluation.alone import _json_ready

        with tempfile.TemporaryDirectory() as tmp:  # its figure is the training physics' one
            metrics = {"task_metrics": _json_ready(evaluator.finish(tmp))}
        metrics["task_metrics"].pop("plot", None)
    return {
        "simulator": "sim2sim: 1 kHz x 20, URDF collision meshes, elliptic cone, Euler, explicit PD",
        "physics_dt_s": cfg.physics_dt_s,
        "pushes": bool(task.pushes.enabled),
        "randomized": params is not None,  # each robot its own friction, payload, CoM draw
        "observation_noise": bool(noise.any()),
        "decimation": decimation,
        "num_envs": n,
        "num_steps": num_steps,
        "survival_fraction": float((~fell).mean()),
        "mean_return": float(returns.mean()),
        "mean_episode_length_steps": float(lengths.mean()),
        **metrics,
    }
