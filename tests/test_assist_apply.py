"""The assist wrench chain end to end: head output -> bound -> mask -> pelvis xfrc_applied in MjData."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import torch
from stand_envs import stand_env

from rl.envs.assist import AssistState, assist_wrench, sample_mask, squash_wrench
from rl.envs.model import CONTROL_SPEC, STATE_SPEC
from rl.envs.state import heading_to_world, world_to_heading
from robots import g1

ETA = torch.tensor([[80.0, 60.0, 200.0, 15.0, 10.0, 5.0]])


def assist_env(num_envs: int, num_threads: int, random_mask_prob: float = 0.2, **overrides):
    env = stand_env(num_envs, num_threads=num_threads, pushes=False, randomize=False, **overrides)
    env.set_assist_bound(ETA)
    env.set_random_mask_prob(random_mask_prob)
    return env


def actions_with_raw(env, raw: torch.Tensor) -> torch.Tensor:
    actions = torch.zeros(env.num_envs, env.num_actions)
    actions[:, g1.NUM_JOINTS :] = raw
    return actions


def pelvis_xfrc(env, data: mujoco.MjData) -> np.ndarray:
    return data.xfrc_applied[env.layout.pelvis_body].copy()


def test_wrench_read_back_from_the_rollout_mjdata():
    """One env, one thread: the rollout's own MjData holds the wrench of the last physics step."""
    env = assist_env(1, 1, random_mask_prob=0.5)
    generator = torch.Generator().manual_seed(7)
    seen_dropped = seen_kept = False
    for _ in range(6):
        raw = 2.0 * torch.randn(1, 6, generator=generator)
        quat = torch.as_tensor(env.state[:, env.layout.qpos][:, 3:7]).float()  # heading this step
        _, _, dones, extras = env.step(actions_with_raw(env, raw))
        assert not dones.any()
        mask = env.assist_mask
        expected_h = mask * ETA * torch.tanh(raw)  # in the robot's heading frame
        expected = heading_to_world(expected_h, quat).double().numpy()[0]
        applied = pelvis_xfrc(env, env.physics_datas[0])
        np.testing.assert_allclose(applied, expected, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(
            extras["assist"]["applied_wrench"][0].numpy(), expected_h.numpy()[0], rtol=1e-6
        )
        assert (extras["assist"]["applied_wrench"].abs() <= ETA + 1e-6).all()
        # the heading rotation keeps the vertical parts and the horizontal magnitudes
        assert applied[2] == pytest.approx(float(expected_h[0, 2]), abs=1e-5)
        assert np.linalg.norm(applied[:2]) == pytest.approx(
            float(expected_h[0, :2].norm()), rel=1e-5
        )
        assert set(mask.unique().tolist()) <= {0.0, 1.0}
        seen_dropped |= bool((mask == 0).any())
        seen_kept |= bool((mask == 1).any())
        # Only the pelvis receives a wrench.
        others = np.delete(env.physics_datas[0].xfrc_applied, env.layout.pelvis_body, axis=0)
        assert not others.any()
    assert seen_dropped and seen_kept
    env.close()


def test_wrench_is_zero_when_disabled_and_after_reset():
    env = assist_env(1, 1, random_mask_prob=0.0)
    raw = torch.full((1, 6), 3.0)
    quat = torch.as_tensor(env.state[:, env.layout.qpos][:, 3:7]).float()
    env.step(actions_with_raw(env, raw))
    np.testing.assert_allclose(
        pelvis_xfrc(env, env.physics_datas[0]),
        heading_to_world(ETA * np.tanh(3.0), quat).numpy()[0],
        rtol=1e-5,
    )
    env.set_assist_enabled(False)
    _, _, _, extras = env.step(actions_with_raw(env, raw))
    assert not pelvis_xfrc(env, env.physics_datas[0]).any()
    assert not extras["assist"]["applied_wrench"].any()
    env.set_assist_enabled(True)
    env.step(actions_with_raw(env, raw))
    env.state[0, env.layout.qpos.start + 2] = 0.1  # force a fall, hence a reset
    _, _, dones, extras = env.step(actions_with_raw(env, raw))
    assert dones[0]
    assert extras["assist"]["applied_wrench"].abs().sum() > 0  # applied during the fatal step
    assert not env.applied_wrench.any()  # cleared with the reset
    assert not env.env_state.applied_wrench.any()
    assert not env.observation_term("critic", "applied_wrench").any()
    env.set_random_mask_prob(1.0)  # zeta = 1 drops every component
    _, _, _, extras = env.step(actions_with_raw(env, raw))
    assert not pelvis_xfrc(env, env.physics_datas[0]).any()


def test_replayed_physics_matches_the_batched_step():
    """Several envs, two threads: replaying each env's state and control row with mj_step on a
    scratch MjData gives the batched result, and the wrench in MjData is the bounded, masked one."""
    env = assist_env(4, 2, random_mask_prob=0.3)
    env.step(actions_with_raw(env, torch.zeros(4, 6)))
    generator = torch.Generator().manual_seed(3)
    actions = torch.randn(4, env.num_actions, generator=generator)
    state_before = env.state.copy()
    _, _, dones, extras = env.step(actions)
    assert not dones.any()
    expected = env.assist_mask * ETA * torch.tanh(actions[:, g1.NUM_JOINTS :])
    torch.testing.assert_close(extras["assist"]["applied_wrench"], expected)
    quat = torch.as_tensor(state_before[:, env.layout.qpos][:, 3:7]).float()
    expected_w = heading_to_world(expected, quat)
    data = mujoco.MjData(env.model)
    for i in range(4):
        mujoco.mj_setState(env.model, data, state_before[i], STATE_SPEC)
        mujoco.mj_setState(env.model, data, env.control[i, 0], CONTROL_SPEC)
        np.testing.assert_allclose(
            pelvis_xfrc(env, data), expected_w[i].double().numpy(), rtol=1e-5, atol=1e-5
        )
        targets = g1.STAND_JOINT_POS_RAD + g1.ACTION_SCALE_RAD * actions[i, :29].double().numpy()
        np.testing.assert_allclose(data.ctrl, targets, atol=1e-6)
        for _ in range(env.cfg.decimation):
            mujoco.mj_step(env.model, data)
        replayed = np.empty(env.layout.nstate)
        mujoco.mj_getState(env.model, data, replayed, STATE_SPEC)
        np.testing.assert_allclose(replayed, env.state[i], rtol=1e-9, atol=1e-9)


def test_wrench_acts_in_world_frame_on_the_pelvis():
    """An upward world force lifts the pelvis, a world-z torque spins it about the vertical,
    whatever the robot's heading."""
    eta = torch.tensor([[0.0, 0.0, 400.0, 0.0, 0.0, 30.0]])
    results = {}
    for name, raw_z in (("none", 0.0), ("assist", 5.0)):
        env = stand_env(3, num_threads=1, pushes=False, randomize=False, seed=1)
        env.set_assist_bound(eta)
        env.set_random_mask_prob(0.0)
        raw = torch.tensor([[0.0, 0.0, raw_z, 0.0, 0.0, raw_z]]).expand(3, 6)
        env.step(actions_with_raw(env, raw))
        qvel = env.state[:, env.layout.qvel]
        omega_w = env.env_state.base_quat_w  # heading differs per env (random yaw at reset)
        results[name] = (qvel[:, 2].copy(), qvel[:, 3:6].copy(), omega_w)
    dvz = results["assist"][0] - results["none"][0]
    assert (dvz > 0.05).all()  # ~ 400 N / 33 kg * 0.02 s less the unloaded feet
    # omega is in the pelvis frame: rotate the change to world and check its vertical part.
    quat = results["assist"][2].double().numpy()
    for i in range(3):
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, quat[i])
        domega_w = rot.reshape(3, 3) @ (results["assist"][1][i] - results["none"][1][i])
        assert domega_w[2] > 0.05
        assert abs(domega_w[2]) > 3 * np.abs(domega_w[:2]).max()


def test_heading_frame_of_the_assist_wrench():
    """fx pushes along the robot's heading, my is the robot's pitch torque, whatever its yaw."""
    yaw = torch.tensor([0.0, math.pi / 2, math.pi])
    quat = torch.stack([torch.cos(yaw / 2), 0 * yaw, 0 * yaw, torch.sin(yaw / 2)], dim=-1)
    push = torch.tensor([[10.0, 0, 5, 0, 3, 1]]).expand(3, 6)
    world = heading_to_world(push, quat)
    torch.testing.assert_close(world[1], torch.tensor([0.0, 10, 5, -3, 0, 1]), atol=1e-5, rtol=0)
    torch.testing.assert_close(world[2], torch.tensor([-10.0, 0, 5, 0, -3, 1]), atol=1e-5, rtol=0)
    torch.testing.assert_close(world[0], push[0])
    torch.testing.assert_close(world_to_heading(world, quat), push, atol=1e-5, rtol=0)


def test_pure_assist_functions():
    raw = torch.linspace(-20, 20, 60).reshape(10, 6)
    bound = torch.rand(10, 6) * 100
    squashed = squash_wrench(raw, bound)
    assert (squashed.abs() <= bound).all()
    mask = sample_mask((20000, 6), 0.2, torch.Generator().manual_seed(0))
    assert mask.mean().item() == pytest.approx(0.8, abs=0.01)
    torch.testing.assert_close(assist_wrench(raw, bound, mask[:10]), mask[:10] * squashed)
    state = AssistState(torch.ones(2, 6), True, 0.0, False)
    with pytest.raises(ValueError, match="finite and >= 0"):
        state.set_bound(-torch.ones(2, 6))
    wrench, bound_env, _ = state.wrench(torch.ones(3, 6), torch.tensor([0, 1, 1]))
    torch.testing.assert_close(wrench, torch.tanh(torch.ones(3, 6)))
    assert bound_env.shape == (3, 6)
