"""Reward terms are pure functions returning (N,), with the values their docstrings promise."""

from __future__ import annotations

import math

import pytest
import torch
from stand_envs import stand_env

from rl.envs.assist import less_assist
from rl.envs.state import EnvState
from rl.tasks import rewards
from robots import g1

N = 7


def batch(*shape: int) -> torch.Tensor:
    return torch.randn(N, *shape, generator=torch.Generator().manual_seed(sum(shape)))


def random_state() -> EnvState:
    """A batch state of random values (terms must not care where it came from)."""
    return EnvState(
        base_pos_w=batch(3), base_quat_w=torch.nn.functional.normalize(batch(4), dim=-1),
        base_lin_vel_w=batch(3), base_lin_vel_b=batch(3), base_ang_vel_b=batch(3),
        projected_gravity_b=batch(3), joint_pos_rad=batch(29), joint_vel_rps=batch(29) * 2,
        joint_torque_nm=batch(29) * 10, foot_contact_force_n=batch(2) * 100,
        foot_pos_w=batch(2, 3), action=batch(29), last_action=batch(29) * 2,
        applied_wrench=batch(6), assist_bound=batch(6).abs(), episode_time_s=batch(1)[:, 0].abs(),
        command=batch(0), phase=torch.zeros(N, dtype=torch.long), num_phases=1,
        randomization_params=batch(5), default_joint_pos_rad=torch.zeros(29),
        effort_limit_nm=torch.ones(29), weight_n=327.0, terminated=batch(1)[:, 0] > 0,
        step_dt_s=0.02, joint_acc_rps2=batch(29) * 50,
        joint_pos_limits_rad=torch.tensor([[-1.0, 1.0]]).expand(29, 2),
        foot_vel_w=batch(2, 3), foot_air_time_s=batch(2).abs(), foot_contact_time_s=batch(2).abs(),
        foot_last_air_time_s=batch(2).abs(), foot_first_contact=batch(2) > 0,
        body_ground_contact=batch(3) > 0, contact_body_names=("pelvis", "left_knee_link", "torso_link"),
    )  # fmt: skip


CASES = {
    "alive": (rewards.alive, {}),
    "upright": (rewards.upright, {"std": 0.25}),
    "base_height": (rewards.base_height, {"target_m": 0.74}),
    "joint_deviation_l2": (rewards.joint_deviation_l2, {}),
    "action_rate_l2": (rewards.action_rate_l2, {}),
    "torques_l2": (rewards.torques_l2, {}),
    "joint_vel_l2": (rewards.joint_vel_l2, {}),
    "base_lin_vel_xy_l2": (rewards.base_lin_vel_xy_l2, {}),
    "base_ang_vel_xy_l2": (rewards.base_ang_vel_xy_l2, {}),
    "feet_contact": (rewards.feet_contact, {"threshold_n": 1.0}),
    "termination": (rewards.termination, {}),
    "joint_acc_l2": (rewards.joint_acc_l2, {}),
    "joint_pos_limits": (rewards.joint_pos_limits, {"soft_ratio": 0.9}),
    "orientation_l2": (rewards.orientation_l2, {}),
    "ang_vel_z_l2": (rewards.ang_vel_z_l2, {}),
    "feet_slide": (rewards.feet_slide, {}),
    "link_ground_contact": (rewards.link_ground_contact, {"bodies": ("left_knee_link",)}),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_terms_are_pure_and_batched(name):
    fn, params = CASES[name]
    state = random_state()
    before = {k: v.clone() for k, v in vars(state).items() if isinstance(v, torch.Tensor)}
    out = fn(state, **params)
    assert out.shape == (N,) and torch.isfinite(out).all()
    torch.testing.assert_close(out, fn(state, **params))  # deterministic
    for key, value in before.items():
        assert torch.equal(getattr(state, key), value), key  # inputs untouched


def test_term_values():
    state = random_state()
    state.projected_gravity_b = torch.tensor([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    result = rewards.upright(state)
    assert result[0] == 1.0 and result[1] < 1e-6
    state.base_pos_w = torch.tensor([[0.0, 0.0, 0.74], [0.0, 0.0, 0.84]])
    assert rewards.base_height(state, 0.74, 0.1).tolist() == pytest.approx([1.0, math.exp(-1.0)])
    state.foot_contact_force_n = torch.tensor([[0.0, 50.0], [30.0, 40.0]])
    assert rewards.feet_contact(state).tolist() == [0.5, 1.0]
    stand = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32)
    state.joint_pos_rad, state.default_joint_pos_rad = stand.expand(2, -1), stand
    assert rewards.joint_deviation_l2(state).abs().max() == 0.0


def test_new_term_values():
    state = random_state()
    state.joint_pos_rad = torch.zeros(N, 29)
    state.joint_pos_rad[0, 3] = 1.5  # 0.5 rad beyond +1
    state.joint_pos_rad[1, 4] = -0.95  # inside [-1, 1], beyond the 0.9 soft range by 0.05
    assert rewards.joint_pos_limits(state)[:2].tolist() == pytest.approx([0.5, 0.0])
    assert rewards.joint_pos_limits(state, soft_ratio=0.9)[:2].tolist() == pytest.approx(
        [0.6, 0.05]
    )
    state.foot_contact_force_n = torch.tensor([[10.0, 0.0]]).expand(N, 2)
    state.foot_vel_w = torch.tensor([[[3.0, 4.0, 9.0], [1.0, 0.0, 0.0]]]).expand(N, 2, 3)
    assert rewards.feet_slide(state)[0] == pytest.approx(5.0)  # only the loaded foot, xy only
    state.body_ground_contact = torch.tensor([[True, False, True]]).expand(N, 3)
    assert rewards.link_ground_contact(state)[0] == 2.0
    assert rewards.link_ground_contact(state, bodies=("left_knee_link",))[0] == 0.0
    with pytest.raises(ValueError, match="no ground-contact sensor"):
        rewards.link_ground_contact(state, bodies=("tail",))


def test_less_assist_reward():
    eta = torch.tensor([[100.0, 0, 0, 0, 0, 0]]).expand(3, 6)
    force = torch.tensor([[0.0] * 6, [100.0, 0, 0, 0, 0, 0], [50.0, 0, 0, 0, 0, 0]])
    assert less_assist(force, eta).tolist() == pytest.approx([1.0, math.exp(-2.0), math.exp(-1.0)])
    # No help possible (eta = 0): full reward, no division by zero.
    assert less_assist(torch.zeros(2, 6), torch.zeros(2, 6)).tolist() == [1.0, 1.0]


def test_env_adds_less_assist_reward_when_switched_on():
    env = stand_env(4, num_threads=1, pushes=False, randomize=False)
    actions = torch.zeros(4, env.num_actions)
    actions[:, 29:] = 1.0
    _, _, _, extras = env.step(actions)
    assert "Reward/less_assist" not in extras["log"]
    env.set_less_assist_reward(True)
    _, _, _, extras = env.step(actions)
    wrench, bound = extras["assist"]["applied_wrench"], extras["assist"]["bound"]
    expected = less_assist(wrench, bound) * env.task.less_assist_weight * env.step_dt_s
    assert extras["log"]["Reward/less_assist"] == pytest.approx(float(expected.mean()))
