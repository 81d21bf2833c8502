"""The deployment bundle: a robot-side script rebuilds the policy's inputs from policy.json alone."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import torch

from rl.agents.export import OnnxMotionPolicy
from rl.envs.config import EnvConfig
from rl.envs.task_schema import quiet
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND
from rl.training.config import ModelConfig, PPOConfig, TrainConfig
from rl.training.runner import train


def robot_side_observation(
    bundle: dict, gyro, quat_wxyz, q, qdot, last_action, lin_vel
) -> np.ndarray:
    """What a deployment script writes from the bundle's text: no import of the project."""
    w, x, y, z = quat_wxyz
    rot = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    default = np.array([j["default_pos_rad"] for j in bundle["joints"]])
    signals = {
        "base_ang_vel": gyro,
        "projected_gravity": rot.T @ np.array([0.0, 0.0, -1.0]),
        "joint_pos": q - default,
        "joint_vel": qdot,
        "last_action": last_action,
        "base_lin_vel": lin_vel,  # the state estimator's pelvis velocity, pelvis frame
    }
    obs = np.zeros(bundle["observation"]["width"])
    for term in bundle["observation"]["terms"]:
        start, stop = term["columns"]
        obs[start:stop] = term["scale"] * signals[term["name"]]
    return obs


def test_bundle_rebuilds_the_observation_and_drives_the_onnx_policy(tmp_path):
    cfg = TrainConfig(
        mode="a2cf", iterations=1, num_steps_per_env=8, env=EnvConfig(num_envs=4, num_threads=2),
        out=str(tmp_path), run_name="deploy", ppo=PPOConfig(num_mini_batches=2, num_learning_epochs=1),
        model=ModelConfig(motion_hidden_dims=(16,), assist_hidden_dims=(8,), critic_hidden_dims=(16,),
                          encoder_hidden_dims=(16,), latent_dim=2),
    )  # fmt: skip
    run = train(cfg, verbose=False).run_dir
    bundle = json.loads((run / "policy.json").read_text())
    assert bundle["format"] == "a2cf-mb-policy/3" and bundle["onnx"] == "policy.onnx"
    assert bundle["control"]["policy_rate_hz"] == 50.0 and len(bundle["joints"]) == 29
    assert bundle["joints"][3]["name"] == "left_knee_joint"
    assert {t["name"] for t in bundle["observation"]["terms"]} == {
        "base_ang_vel", "projected_gravity", "joint_pos", "joint_vel", "last_action",
        "base_lin_vel"}  # fmt: skip
    env = make_env(quiet(STAND), 2, num_threads=1)  # noise-free: the robot's true signals
    policy = OnnxMotionPolicy(run / bundle["onnx"])
    h = bundle["observation"]["history_length"]
    history: list[np.ndarray] = []
    last_action = np.zeros((2, 29))
    obs = env.get_observations()
    for _ in range(6):
        s = env.env_state
        rows = [
            robot_side_observation(
                bundle,
                s.base_ang_vel_b[i].numpy(),
                s.base_quat_w[i].numpy(),
                s.joint_pos_rad[i].numpy(),
                s.joint_vel_rps[i].numpy(),
                last_action[i],
                s.base_lin_vel_b[i].numpy(),
            )  # fmt: skip
            for i in range(2)
        ]
        mine = np.stack(rows)
        np.testing.assert_allclose(mine, obs["policy"].numpy(), atol=1e-5)
        history = (history or [mine] * h)[1:] + [mine]
        np.testing.assert_allclose(
            np.concatenate(history, axis=1), obs["history"].numpy(), atol=1e-5
        )
        actions = policy(
            mine.astype(np.float32), np.concatenate(history, axis=1).astype(np.float32)
        )
        obs, _, dones, _ = env.step(torch.cat([torch.from_numpy(actions), torch.zeros(2, 6)], -1))
        assert not dones.any()
        last_action = actions

    # The same bundle drives the second simulator (1 kHz, meshes, explicit PD), scored by the task.
    from rl.evaluation.sim2sim import Sim2SimConfig, build_sim2sim_model, run_sim2sim

    model = build_sim2sim_model(Sim2SimConfig())
    assert model.opt.timestep == 0.001 and model.nu == 0 and model.nmesh > 0
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    other = run_sim2sim(run, STAND, num_steps=10, cfg=Sim2SimConfig(num_envs=2))
    assert other["decimation"] == 20 and other["survival_fraction"] == 1.0
    # 10 steps of a near-neutral policy: per-step rewards like the training physics' (alive ~0.02)
    assert 0.5 * 10 * 0.02 < other["mean_return"] < 2.0 * 10 * 0.07
