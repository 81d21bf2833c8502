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

The task's own termination and reward terms score the rollouts (same metrics as ``eval``), so the
two columns compare like with like. Tasks with a command are not supported here yet (a clear
error).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from rl.envs.state import EnvState, quat_rotate_inverse
from rl.envs.vec_env import GRAVITY_MPS2
from rl.export import OnnxMotionPolicy
from rl.tasks.config import TaskConfig
from robots import g1
from robots.mujoco_model import STAND_KEYFRAME, MujocoModelConfig, build_mujoco_spec


@dataclass(frozen=True)
class Sim2SimConfig:
    """The second simulator's settings and the rollout size."""

    num_envs: int = 8  # independent robots (one MjData each) [-]
    physics_dt_s: float = 0.001  # physics step [s]
    impratio: float = 10.0  # frictional-to-normal impedance ratio of the elliptic cone [-]
    joint_pos_noise_rad: float = 0.05  # uniform +- initial joint offset from the default pose [rad]
    seed: int = 1  # initial-state seed [-]

    def __post_init__(self) -> None:
        if self.num_envs < 1 or self.physics_dt_s <= 0:
            raise ValueError("sim2sim needs num_envs >= 1 and a positive physics step")


def build_sim2sim_model(cfg: Sim2SimConfig) -> mujoco.MjModel:
    """The G1 with its URDF collision meshes on the floor, no actuators (torques are explicit)."""
    spec = build_mujoco_spec(
        MujocoModelConfig(timestep_s=cfg.physics_dt_s, body_floor_collision=True, actuators=False)
    )
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = cfg.impratio
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    return spec.compile()


def bundle_observation(bundle: dict, gyro, quat_wxyz, q, qdot, last_action) -> np.ndarray:
    """One robot's policy observation from raw signals, as the bundle describes it."""
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
    }
    obs = np.zeros(bundle["observation"]["width"])
    for term in bundle["observation"]["terms"]:
        if term["name"] not in signals:
            raise ValueError(f"sim2sim cannot compute observation term '{term['name']}' yet")
        start, stop = term["columns"]
        obs[start:stop] = term["scale"] * signals[term["name"]]
    return obs


def _state(model, datas, task: TaskConfig, tau, action, last_action, time_s) -> EnvState:
    """The batch EnvState of the sim2sim robots (assistance off), for the task's terms."""
    qpos = torch.tensor(np.stack([d.qpos for d in datas]), dtype=torch.float32)
    qvel = torch.tensor(np.stack([d.qvel for d in datas]), dtype=torch.float32)
    n = qpos.shape[0]
    quat = qpos[:, 3:7]
    touch = [model.sensor(f"{s}_touch") for s in g1.SOLE_FRAMES]
    sites = [model.site(s).id for s in g1.SOLE_FRAMES]
    contact = torch.tensor([[d.sensordata[t.adr[0]] for t in touch] for d in datas]).float()
    feet = torch.tensor(np.stack([[d.site_xpos[i] for i in sites] for d in datas])).float()
    zeros6 = torch.zeros(n, 6)
    limits = torch.tensor(np.array([model.joint(j.name).range for j in g1.JOINTS])).float()
    mass = float(model.body_subtreemass[0])
    return EnvState(
        base_pos_w=qpos[:, :3], base_quat_w=quat, base_lin_vel_w=qvel[:, :3],
        base_lin_vel_b=quat_rotate_inverse(quat, qvel[:, :3]), base_ang_vel_b=qvel[:, 3:6],
        projected_gravity_b=quat_rotate_inverse(quat, torch.tensor([0.0, 0, -1]).expand(n, 3)),
        joint_pos_rad=qpos[:, 7:], joint_vel_rps=qvel[:, 6:],
        joint_torque_nm=torch.tensor(tau).float(), foot_contact_force_n=contact, foot_pos_w=feet,
        action=torch.tensor(action).float(), last_action=torch.tensor(last_action).float(),
        applied_wrench=zeros6, assist_bound=zeros6, episode_time_s=torch.full((n,), time_s),
        command=torch.zeros(n, 0), phase=torch.zeros(n, dtype=torch.long),
        num_phases=task.num_phases, randomization_params=torch.zeros(n, 5),
        default_joint_pos_rad=torch.tensor(g1.STAND_JOINT_POS_RAD).float(),
        effort_limit_nm=torch.tensor(g1.EFFORT_LIMIT_NM).float(), weight_n=mass * GRAVITY_MPS2,
        terminated=torch.zeros(n, dtype=torch.bool), step_dt_s=0.0,
        joint_acc_rps2=torch.zeros(n, 29), joint_pos_limits_rad=limits,
        foot_vel_w=torch.zeros(n, 2, 3), foot_air_time_s=torch.zeros(n, 2),
        foot_contact_time_s=torch.zeros(n, 2), foot_last_air_time_s=torch.zeros(n, 2),
        foot_first_contact=torch.zeros(n, 2, dtype=torch.bool),
        body_ground_contact=torch.zeros(n, 0, dtype=torch.bool), contact_body_names=(),
    )  # fmt: skip


def run_sim2sim(run_dir: str | Path, task: TaskConfig, num_steps: int,
                cfg: Sim2SimConfig = Sim2SimConfig()) -> dict[str, Any]:  # fmt: skip
    """Roll the exported policy of ``run_dir`` out in the second simulator; survival and return."""
    run_dir = Path(run_dir)
    bundle_path = run_dir / "policy.json"
    bundle = json.loads(bundle_path.read_text())
    if "joints" not in bundle:
        raise ValueError(f"{bundle_path} has no deployment bundle (exported before format 2)")
    if task.commands.dim:
        raise ValueError(f"sim2sim does not drive task commands yet ('{task.name}' has one)")
    policy = OnnxMotionPolicy(run_dir / bundle["onnx"])
    model = build_sim2sim_model(cfg)
    decimation = round(1.0 / bundle["control"]["policy_rate_hz"] / cfg.physics_dt_s)
    joints = bundle["joints"]
    kp, kd = np.array([j["kp"] for j in joints]), np.array([j["kd"] for j in joints])
    effort = np.array([j["effort_limit_nm"] for j in joints])
    default = np.array([j["default_pos_rad"] for j in joints])
    scale = np.array([j["action_scale_rad"] for j in joints])
    h = bundle["observation"]["history_length"]
    rng = np.random.default_rng(cfg.seed)
    n = cfg.num_envs
    datas = []
    for _ in range(n):
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
        data.qpos[7:] += rng.uniform(-1, 1, 29) * cfg.joint_pos_noise_rad
        yaw = rng.uniform(-math.pi, math.pi)
        data.qpos[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        mujoco.mj_forward(model, data)
        datas.append(data)
    last_action = np.zeros((n, 29))
    tau = np.zeros((n, 29))
    history = [None] * n
    active = np.ones(n, dtype=bool)
    fell = np.zeros(n, dtype=bool)
    returns = np.zeros(n)
    lengths = np.zeros(n)
    dt = decimation * cfg.physics_dt_s
    for step in range(num_steps):
        obs = np.stack([
            bundle_observation(bundle, d.qvel[3:6], d.qpos[3:7], d.qpos[7:], d.qvel[6:], last_action[i])
            for i, d in enumerate(datas)
        ])  # fmt: skip
        for i in range(n):
            history[i] = [obs[i]] * h if history[i] is None else history[i][1:] + [obs[i]]
        hist = np.stack([np.concatenate(hh) for hh in history]).astype(np.float32)
        action = np.clip(
            policy(obs.astype(np.float32), hist), -bundle["clip_actions"], bundle["clip_actions"]
        )
        target = default + scale * action
        for i, data in enumerate(datas):
            if not active[i]:
                continue
            for _ in range(decimation):
                tau[i] = np.clip(
                    kp * (target[i] - data.qpos[7:]) - kd * data.qvel[6:], -effort, effort
                )
                data.qfrc_applied[6:] = tau[i]
                mujoco.mj_step(model, data)
        state = _state(model, datas, task, tau, action, last_action, (step + 1) * dt)
        failed = torch.stack([t(state) for t in task.terminations]).any(dim=0).numpy()
        state.terminated = torch.from_numpy(failed)
        reward = sum(t(state) * (t.weight * dt) for t in task.rewards).numpy()
        returns += np.where(active, reward, 0.0)
        lengths += active
        fell |= active & failed
        active &= ~failed
        last_action = action
        if not active.any():
            break
    return {
        "simulator": "sim2sim: 1 kHz x 20, URDF collision meshes, elliptic cone, Euler, explicit PD",
        "physics_dt_s": cfg.physics_dt_s,
        "decimation": decimation,
        "num_envs": n,
        "num_steps": num_steps,
        "survival_fraction": float((~fell).mean()),
        "mean_return": float(returns.mean()),
        "mean_episode_length_steps": float(lengths.mean()),
    }
