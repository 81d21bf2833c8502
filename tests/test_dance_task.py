"""The dance task: zero tracking error on the reference, reward terms against hand values, resets
on the floor for hovering / sinking clips, the skill measure, training and eval."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from test_training import tiny_config

from rl.envs.task_schema import quiet
from rl.evaluation.policy import EvalConfig, evaluate
from rl.tasks.dance import terms as dt
from rl.tasks.dance.skill import TrackingSkillConfig
from rl.tasks.dance.task import DANCE_JOINTS as DANCE
from rl.tasks.dance.task import DANCE_PAPER, dance_task
from rl.tasks.registry import get_task, make_env
from rl.training.runner import train


@pytest.fixture(scope="module")
def hovering_clip(tmp_path_factory, g1_pin) -> str:
    """A 30 fps NPZ clip of the stand pose whose pelvis bobs +-3 cm (feet hover and sink) while
    the arms wave."""
    frames = 60
    t = np.arange(frames) / 30.0
    q = np.tile(g1_pin.q_stand, (frames, 1))
    q[:, 2] += 0.03 * np.sin(2 * np.pi * 0.8 * t)
    q[:, 7 + 15] += 0.4 * np.sin(2 * np.pi * 0.5 * t)  # left shoulder pitch
    path = tmp_path_factory.mktemp("clips") / "bob.npz"
    np.savez(path, qpos=q, fps=30.0)
    return str(path)


def test_tracking_error_is_exactly_zero_on_the_reference() -> None:
    env = make_env(quiet(DANCE), 3, num_threads=1)
    try:
        cmd, lay = env.command_gen, env.layout
        frames = cmd.frame(ahead=1).numpy()  # the frames the current command targets
        torch.testing.assert_close(
            cmd.reference_time_s(), torch.as_tensor(frames - 1, dtype=torch.float64) * 0.02
        )
        qpos = cmd.library.qpos[frames].copy()
        qpos[:, 2] += cmd.z_offset_m.numpy()
        env.state[:, lay.qpos] = qpos
        env.state[:, lay.qvel] = cmd.library.qvel[frames]
        s = env._read_state()
        assert torch.equal(s.command, env.command)
        for term in (dt.base_displacement_error_sq, dt.base_rotation_error_sq, dt.joint_error_sq):
            assert term(s).abs().max() == 0.0, term.__name__
        for term in DANCE.rewards[:3]:
            assert torch.equal(term(s), torch.ones(3)), term.name
        # One frame off, the joint error is not zero (the test can fail).
        env.state[:, lay.qpos] = cmd.library.qpos[frames - 1]
        assert dt.joint_error_sq(env._read_state()).min() > 0.0
    finally:
        env.close()


def test_reward_terms_against_hand_values() -> None:
    env = make_env(quiet(DANCE), 2, num_threads=1)
    try:
        s0 = env.env_state
    finally:
        env.close()
    yaw90 = torch.tensor([[math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)], [1.0, 0, 0, 0]])
    vel = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # env 0: forward in its heading
    ang = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    command = torch.zeros(2, dt.COMMAND_DIM)
    command[:, 0] = 0.01  # the reference moves 1 cm forward per step
    command[:, 3] = 1.0  # and does not turn
    joints = torch.zeros(2, 29)
    joints[1, 0], joints[1, 5] = 0.5, 1.0
    s = dataclasses.replace(s0, base_quat_w=yaw90, base_lin_vel_w=vel, base_ang_vel_b=ang,
                            command=command, joint_pos_rad=joints)  # fmt: skip
    # dp = v dt = 2 cm forward for both: error 1 cm.
    torch.testing.assert_close(dt.base_displacement_error_sq(s), torch.tensor([1e-4, 1e-4]))
    torch.testing.assert_close(dt.track_base_position(s), torch.full((2,), math.exp(-0.25)))
    rot_err = (1 - math.cos(0.01)) ** 2 + math.sin(0.01) ** 2
    torch.testing.assert_close(
        dt.track_base_rotation(s), torch.tensor([math.exp(-100 * rot_err), 1.0])
    )
    torch.testing.assert_close(dt.track_joint_position(s), torch.tensor([1.0, math.exp(-0.3125)]))
    torch.testing.assert_close(dt.joint_error_mean_abs(s), torch.tensor([0.0, 1.5 / 29]))
    # the steep term: exp(-(rms / 0.2)^2), rms = sqrt(1.25 / 29) for env 1
    torch.testing.assert_close(
        dt.track_joint_rms(s, std_rad=0.2), torch.tensor([1.0, math.exp(-1.25 / 29 / 0.04)])
    )
    paper = {"base_position": 10.0, "base_rotation": 5.0, "joint_position": 20.0,
             "feet_slide": -1.0, "action_rate": -0.01, "joint_acc": -2.5e-7, "torques": -1e-5}  # fmt: skip
    assert {t.name: t.weight for t in DANCE_PAPER.rewards} == paper
    recipe = {**paper, "joint_position": 5.0, "joint_rms": 15.0, "termination": -100.0}
    assert {t.name: t.weight for t in DANCE.rewards} == recipe
    assert DANCE.less_assist_weight == 2.0 == DANCE_PAPER.less_assist_weight


def test_resets_put_a_hovering_clip_on_the_floor(hovering_clip) -> None:
    task = quiet(dance_task((hovering_clip,)))
    assert hovering_clip in task.description
    task = dataclasses.replace(task, commands=dataclasses.replace(task.commands, min_frames_left=5))
    env = make_env(task, 8, num_threads=1)
    stand = make_env(quiet(get_task("stand")), 1, num_threads=1)
    try:
        lib = env.command_gen.library
        assert lib.qpos.shape[0] == 99  # 59 / 30 s resampled from 30 to 50 fps
        assert np.ptp(lib.floor_shift_m) > 0.05  # the clip's feet hover up to ~6 cm
        frames = env.command_gen.start_frame.numpy()
        assert len(set(frames.tolist())) > 1  # start frames sampled along the clip
        sole_z = env.env_state.foot_pos_w[:, :, 2]
        stand_z = stand.env_state.foot_pos_w[0, :, 2]
        torch.testing.assert_close(sole_z, stand_z.expand(8, 2), atol=1e-5, rtol=0)
        # The robot stays on its frame: joints exactly the reference frame's.
        np.testing.assert_array_equal(env.state[:, env.layout.qpos][:, 7:], lib.qpos[frames, 7:])
    finally:
        env.close()
        stand.close()


def test_skill_is_threshold_over_episode_error() -> None:
    env = make_env(quiet(DANCE), 2, num_threads=1)
    try:
        s = env.env_state
    finally:
        env.close()
    skill = TrackingSkillConfig(window=4).build(max_episode_length=100)
    assert skill.progress() == 0.0
    joints = s.command[:, 7:].clone()
    joints[0] += 0.08  # mean abs error 0.08 rad: half the threshold
    s = dataclasses.replace(s, joint_pos_rad=joints)
    skill.on_episodes_end(torch.tensor([0]), torch.tensor([True]), torch.tensor([100]), s)
    assert skill.progress() == pytest.approx(2.0, rel=1e-5)
    skill.on_episodes_end(torch.tensor([1]), torch.tensor([False]), torch.tensor([10]), s)
    assert skill.mean_error_rad() == pytest.approx((0.08 + 1.0) / 2, rel=1e-5)  # a fall: 1 rad


def test_two_training_iterations_and_eval_with_task_metrics(tmp_path) -> None:
    result = train(tiny_config(tmp_path, "a2cf", task="dance-joints"), verbose=False)
    assert result.iterations_done == 2
    report = evaluate(result.run_dir, EvalConfig(num_envs=2, num_steps=10))
    metrics = report["task_metrics"]
    for key in ("joint_legs_rad", "joint_waist_rad", "joint_arms_rad", "base_position_m",
                "base_orientation_rad"):  # fmt: skip
        assert math.isfinite(metrics[key]) and metrics[key] >= 0.0
    assert metrics["steps"] >= 1 and (result.run_dir / "eval_dance.png").is_file()


def test_eval_skill_charges_falls_like_the_training_measure(tmp_path) -> None:
    """A policy that tracks well until it falls has not learned the dance: eval's
    ``skill_learned`` charges a fall ``fall_error_rad`` (it used to average the error over the
    steps before the falls only, and said "learned" with every episode fallen)."""
    env = make_env(quiet(DANCE), 2, num_threads=1)
    try:
        evaluator = DANCE.evaluation.build(env)
        active = torch.ones(2, dtype=torch.bool)
        env.step(torch.zeros(2, env.num_actions))
        no_timeout = {"time_outs": torch.zeros(2)}
        evaluator.on_step(env, active, torch.zeros(2), no_timeout)  # both on the reference
        evaluator.on_step(env, active, torch.tensor([1.0, 0.0]), no_timeout)  # env 0 falls
        metrics = evaluator.finish(tmp_path)
    finally:
        env.close()
    assert metrics["joint_all_rad"] < DANCE.skill.threshold_rad  # tracking was fine meanwhile
    assert metrics["fell_fraction"] == 0.5
    assert metrics["skill_error_rad"] > (1.0 + 0.0) / 2 - 1e-6
    assert metrics["skill_learned"] is False
