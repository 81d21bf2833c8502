"""Reward terms are pure functions returning (N,), with the values their docstrings promise."""

from __future__ import annotations

import math

import pytest
import torch

from rl import rewards
from rl.envs import make_env
from robots import g1

N = 7


def batch(*shape: int) -> torch.Tensor:
    return torch.randn(N, *shape, generator=torch.Generator().manual_seed(sum(shape)))


CASES = {
    "alive": (rewards.alive, (batch(3),)),
    "upright": (rewards.upright, (batch(3),)),
    "base_height": (rewards.base_height, (batch(1)[:, 0], 0.74)),
    "joint_deviation_l2": (rewards.joint_deviation_l2, (batch(29), torch.zeros(29))),
    "action_rate_l2": (rewards.action_rate_l2, (batch(29), batch(29) * 2)),
    "torques_l2": (rewards.torques_l2, (batch(29),)),
    "joint_vel_l2": (rewards.joint_vel_l2, (batch(29),)),
    "base_lin_vel_xy_l2": (rewards.base_lin_vel_xy_l2, (batch(3),)),
    "base_ang_vel_xy_l2": (rewards.base_ang_vel_xy_l2, (batch(3),)),
    "feet_contact": (rewards.feet_contact, (batch(2) * 100,)),
    "termination": (rewards.termination, (batch(1)[:, 0] > 0,)),
    "less_assist": (rewards.less_assist, (batch(6), batch(6).abs())),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_terms_are_pure_and_batched(name):
    fn, args = CASES[name]
    copies = [a.clone() if isinstance(a, torch.Tensor) else a for a in args]
    out = fn(*args)
    assert out.shape == (N,) and torch.isfinite(out).all()
    again = fn(*args)
    torch.testing.assert_close(out, again)  # deterministic
    for a, c in zip(args, copies, strict=True):
        if isinstance(a, torch.Tensor):
            assert torch.equal(a, c)  # inputs untouched


def test_term_values():
    upright_g = torch.tensor([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    result = rewards.upright(upright_g)
    assert result[0] == 1.0 and result[1] < 1e-6
    assert rewards.base_height(torch.tensor([0.74, 0.84]), 0.74, 0.1).tolist() == pytest.approx(
        [1.0, math.exp(-1.0)]
    )
    assert rewards.feet_contact(torch.tensor([[0.0, 50.0], [30.0, 40.0]])).tolist() == [0.5, 1.0]
    stand = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32)
    assert rewards.joint_deviation_l2(stand.expand(2, -1), stand).abs().max() == 0.0


def test_less_assist_reward():
    eta = torch.tensor([[100.0, 0, 0, 0, 0, 0]]).expand(3, 6)
    force = torch.tensor([[0.0] * 6, [100.0, 0, 0, 0, 0, 0], [50.0, 0, 0, 0, 0, 0]])
    assert rewards.less_assist(force, eta).tolist() == pytest.approx(
        [1.0, math.exp(-2.0), math.exp(-1.0)]
    )
    # No help possible (eta = 0): full reward, no division by zero.
    assert rewards.less_assist(torch.zeros(2, 6), torch.zeros(2, 6)).tolist() == [1.0, 1.0]


def test_env_adds_less_assist_reward_when_switched_on():
    env = make_env("stand", 4, num_threads=1, pushes=False, randomize=False)
    actions = torch.zeros(4, env.num_actions)
    actions[:, 29:] = 1.0
    _, _, _, extras = env.step(actions)
    assert "Reward/less_assist" not in extras["log"]
    env.set_less_assist_reward(True)
    _, _, _, extras = env.step(actions)
    wrench, bound = extras["assist"]["applied_wrench"], extras["assist"]["bound"]
    expected = rewards.less_assist(wrench, bound) * env.task.less_assist_weight * env.step_dt_s
    assert extras["log"]["Reward/less_assist"] == pytest.approx(float(expected.mean()))
