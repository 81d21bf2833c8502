"""The backflip task: FSM on scripted states, reward terms against hand values, per-phase Algorithm 1
on the real env, failure on link contacts, success measure, oracle poses, training and eval."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from test_training import tiny_config

from optimal_control.bounds import PAPER_ETA0
from rl.a2cf.algorithm1 import Algorithm1, RecordingEnv
from rl.a2cf.config import PAPER_RULES, CurriculumConfig
from rl.a2cf.curriculum import AssistCurriculum
from rl.envs.state import EnvState
from rl.envs.task_schema import quiet
from rl.evaluation.policy import EvalConfig, evaluate
from rl.tasks.backflip import terms as bt
from rl.tasks.backflip.task import BACKFLIP, backflip_task
from rl.tasks.registry import get_task, make_env
from rl.training.runner import train
from robots import g1

N = 5


@pytest.fixture(scope="module")
def template() -> EnvState:
    """A real batch state of N backflip envs (fields the tests overwrite)."""
    env = make_env(quiet(BACKFLIP), N, num_threads=1)
    try:
        return env.env_state
    finally:
        env.close()


def scripted(template: EnvState, **fields) -> EnvState:
    """The template state with some fields replaced (tensors of N envs)."""
    return dataclasses.replace(template, **fields)


def _quat_axis(axis: int, angle: float) -> torch.Tensor:
    q = torch.zeros(4)
    q[0] = math.cos(angle / 2)
    q[1 + axis] = math.sin(angle / 2)
    return q


def test_fsm_walks_the_five_phases_and_ignores_a_landing_before_half_a_turn(template) -> None:
    fsm = bt.BackflipPhasesConfig().build(N, torch.Generator())
    fsm.reset(torch.arange(N))
    loaded = torch.full((N, 2), 200.0)
    air = torch.zeros(N, 2)
    high = template.base_pos_w.clone()
    high[:, 2] = 0.75
    low = high.clone()
    low[:, 2] = 0.55
    still = torch.zeros(N, 3)
    on = torch.ones(N, 1)
    base = {"foot_contact_force_n": loaded, "base_pos_w": high, "base_ang_vel_b": still}

    # A freshly reset env still shows its former episode's command: no start on that update.
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.STAND] * N
    off = torch.zeros(N, 1)
    assert fsm.update(scripted(template, command=off, **base)).tolist() == [bt.STAND] * N
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.CROUCH] * N
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.CROUCH] * N
    base["base_pos_w"] = low  # crouched below 0.62 m
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.JUMP] * N
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.JUMP] * N
    # Env 0 keeps one sole down, the others take off.
    one_sole = air.clone()
    one_sole[0, 0] = 50.0
    base["foot_contact_force_n"] = one_sole
    assert fsm.update(scripted(template, command=on, **base)).tolist() == [bt.JUMP] + [bt.AIR] * 4
    # Flip backward at -w_y = 10 rad/s: 0.2 rad per 0.02 s step.
    spin = torch.zeros(N, 3)
    spin[:, 1] = -10.0
    air = one_sole  # env 0 stays on one sole (in Jump) throughout
    base.update(base_ang_vel_b=spin, foot_contact_force_n=air)
    turned0 = fsm.turned_rad.clone()
    for _ in range(5):
        fsm.update(scripted(template, command=on, **base))
    torch.testing.assert_close(fsm.turned_rad[1:] - turned0[1:], torch.full((4,), 1.0))
    # Env 1 touches down after ~1 rad (+ the crouch/jump steps: still < pi): not a landing.
    touch = air.clone()
    touch[1] = 200.0
    phase = fsm.update(scripted(template, command=on, **{**base, "foot_contact_force_n": touch}))
    assert phase[1] == bt.AIR and bool(fsm.landed_short[1])
    assert not fsm.landed_short[2:].any()
    for _ in range(10):  # the rest turn on past pi
        fsm.update(scripted(template, command=on, **base))
    assert (fsm.turned_rad[2:] >= math.pi).all()
    touch = air.clone()
    touch[2:, 1] = 200.0
    phase = fsm.update(scripted(template, command=on, **{**base, "foot_contact_force_n": touch}))
    assert phase.tolist() == [bt.JUMP, bt.AIR, bt.LAND, bt.LAND, bt.LAND]
    assert fsm.max_phase.tolist() == [bt.JUMP, bt.AIR, bt.LAND, bt.LAND, bt.LAND]
    # Land is final; a reset records the episode and goes back to Stand.
    assert fsm.update(scripted(template, command=on, **base))[2:].tolist() == [bt.LAND] * 3
    fsm.reset(torch.tensor([1, 2]))
    assert fsm.phase[1] == bt.STAND and fsm.phase[2] == bt.STAND
    assert fsm.last_max_phase[2] == bt.LAND and bool(fsm.last_landed_short[1])
    assert not fsm.landed_short[1] and fsm.turned_rad[2] == 0.0


def test_reward_terms_against_hand_values(template) -> None:
    phase = torch.tensor([0, 1, 2, 3, 4])
    vel = torch.tensor([[0.0, 0.0, -0.5], [0.0, 0.0, -0.5], [0.0, 0.0, 2.0], [0.3, 0.0, 0.4],
                        [0.3, 0.0, 0.4]])  # fmt: skip
    ang = torch.tensor([[0.0, -1.0, 0.5], [0.0, -1.0, 0.0], [0.0, -4.0, 0.0], [0.0, -6.0, -2.0],
                        [0.0, 0.0, 0.0]])  # fmt: skip
    quat = torch.stack([_quat_axis(1, 0.3), _quat_axis(1, 0.3), _quat_axis(0, 0.2),
                        _quat_axis(1, 2.0), _quat_axis(1, 0.1)])  # fmt: skip
    from rl.envs.state import quat_rotate_inverse

    gravity = quat_rotate_inverse(quat, torch.tensor([0.0, 0.0, -1.0]).expand(N, 3))
    contact = torch.tensor([[100.0, 100.0], [100.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    poses = bt.desired_joint_poses()
    joints = poses[phase].clone()
    joints[1, 0] += 0.3
    joints[1, 3] += 0.4  # |q - q_des| = 0.5 in the crouch
    s = scripted(template, phase=phase, base_lin_vel_w=vel, base_ang_vel_b=ang, base_quat_w=quat,
                 projected_gravity_b=gravity, foot_contact_force_n=contact,
                 joint_pos_rad=joints)  # fmt: skip

    def close(value, expected):
        torch.testing.assert_close(value, torch.tensor(expected), atol=1e-5, rtol=1e-5)

    close(bt.phase_alive(s), [1.0, 0, 0, 0, 0])
    close(bt.down_velocity_in_contact(s), [0.0, 0.5, 0, 0, 0])
    close(bt.up_velocity(s), [0.0, 0, 2.0, 0, 0])
    close(bt.backward_pitch_rate(s, phases=(bt.JUMP,)), [0.0, 0, 4.0, 0, 0])
    close(bt.backward_pitch_rate(s, phases=(bt.AIR,)), [0.0, 0, 0, 6.0, 0])
    close(bt.land_still(s), [0.0, 0, 0, 0, math.exp(-10 * 0.5)])
    close(bt.tilt_angle(s), [0.3, 0.3, 0, 0, 0.1])
    close(bt.lateral_axis_angle(s), [0.0, 0, 0.2, 0.0, 0])  # a pitch turn keeps y_base = y_world
    close(bt.yaw_rate_abs(s), [0.5, 0, 0, 2.0, 0])
    close(bt.phase_pose_deviation(s), [0.0, 0.5, 0, 0, 0])
    # The task lists exactly the paper's table (weights), each term once.
    weights = {t.name: t.weight for t in BACKFLIP.rewards}
    assert weights == {
        "alive": 2.0, "down_velocity": 2.0, "up_velocity": 2.0, "pitch_rate_jump": 0.5,
        "pitch_rate_air": 2.0, "land": 20.0, "balance_ground": -2.0, "balance_flight": -2.0,
        "yaw_rate": -0.1, "action_rate": -0.01, "joint_acc": -2.5e-7, "joint_limits": -1.0,
        "pose_deviation": -0.2,
    }  # fmt: skip
    assert BACKFLIP.less_assist_weight == 1.0


def test_success_needs_land_held_upright_and_still(template) -> None:
    cfg = bt.BackflipSkillConfig(window=8, target_success=0.5)
    skill = cfg.build(max_episode_length=200)
    held = torch.tensor([[1.2, 1.1], [1.2, 1.1], [0.5, 1.1], [1.2, 1.1], [1.2, 1.2]])
    speed = torch.tensor([[0.0, 0, 0], [0.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0], [0.0, 0, 0]])
    s = scripted(template, phase=torch.tensor([4, 3, 4, 4, 4]), foot_contact_time_s=held,
                 base_lin_vel_w=speed)  # fmt: skip
    ids = torch.arange(N)
    time_outs = torch.tensor([True, True, True, True, False])  # env 4 failed (terminated)
    skill.on_episodes_end(ids, time_outs, torch.full((N,), 200), s)
    # Only env 0: Land, both soles loaded for >= 1 s, still, and the episode timed out.
    assert skill.last_success.tolist() == [True, False, False, False, False]
    assert skill.success_rate() == pytest.approx(0.2)
    assert skill.progress() == pytest.approx(0.4)
    # A time-out of a shortened episode (random runner start) is not counted.
    skill.on_episodes_end(ids[:1], time_outs[:1], torch.tensor([10]), s)
    assert skill.success_rate() == pytest.approx(0.2)


def test_a_landing_on_the_knees_is_a_failure_in_the_real_env() -> None:
    env = make_env(quiet(BACKFLIP), 2, num_threads=1)
    try:
        lay = env.layout
        q = env.state[:, lay.qpos]
        q[1, 2] = 0.4  # env 1 kneels upright: knees bent 90 deg, thighs vertical, pelvis 0.4 m
        for side in ("left", "right"):
            for joint, angle in (("knee", 1.57), ("hip_pitch", 0.0), ("ankle_pitch", 0.0)):
                q[1, 7 + g1.JOINT_NAMES.index(f"{side}_{joint}_joint")] = angle
        env.state[:, lay.qpos] = q
        _, _, dones, extras = env.step(torch.zeros(2, 35))
        assert dones.tolist() == [False, True]
        log = extras["log"]
        assert log["Termination/link_on_ground"] == pytest.approx(0.5)
        assert log["Termination/too_low"] == 0.0 and log["Termination/fell"] == 0.0
        assert not extras["time_outs"].any()
    finally:
        env.close()


def test_per_phase_bounds_follow_algorithm_1_independently_in_the_real_env() -> None:
    # Start at once: after the first steps every env crouches (start delay 0).
    task = dataclasses.replace(
        quiet(BACKFLIP), commands=bt.StartCommandConfig(delay_range_s=(0.0, 0.0))
    )
    env = make_env(task, 4, num_threads=1)
    try:
        eta0 = env.task.default_assist_bound()
        torch.testing.assert_close(eta0, torch.tensor(PAPER_ETA0["backflip"]["all"]).float())
        assert not torch.allclose(eta0[0], eta0[2])  # the paper's rows differ per phase
        env.set_random_mask_prob(0.0)
        learner = RecordingEnv(
            env, Algorithm1(AssistCurriculum(eta0, CurriculumConfig(**PAPER_RULES)))
        )
        for _ in range(6):
            # No help in Stand (|F| = 0 << |eta|), full help in Crouch (|F| ~ |eta|: in the band).
            raw = torch.where((env.phase == bt.CROUCH).unsqueeze(-1), 20.0, 0.0).expand(4, 6)
            learner.step(torch.cat([torch.zeros(4, 29), raw], dim=-1))
        row = learner.end_iteration()  # the runner's, once per iteration
        event = learner.algorithm
        eta = event.curriculum.eta
        assert event.iteration == 1
        visited = row["visited"]
        assert visited[:2] == [True, True] and visited[2:] == [False] * 3
        torch.testing.assert_close(eta[0], eta0[0] * 0.8)  # Stand: shrunk
        torch.testing.assert_close(eta[1], eta0[1])  # Crouch: kept
        torch.testing.assert_close(eta[2:], eta0[2:])  # unvisited: kept
        torch.testing.assert_close(env.assist.bound, eta)  # applied from the next step on
    finally:
        env.close()


def test_desired_poses_from_an_oracle_artifact(tmp_path, g1_pin) -> None:
    from optimal_control.artifact import build_artifact
    from optimal_control.reference import static_reference
    from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig

    ref = static_reference(g1_pin.q_stand, 10, 0.02, name="flip")
    ref.phase = np.array([0, 0, 1, 1, 2, 2, 3, 3, 4, 4])
    ref.phase_names = bt.BACKFLIP_PHASES
    knee = 7 + g1.JOINT_NAMES.index("left_knee_joint")
    ref.q[:, knee] = np.linspace(0.2, 1.1, 10)
    ref.validate()
    profile = {0.5: WrenchQP(WrenchQPConfig(alpha=0.5)).solve_reference(ref)}
    art = build_artifact("backflip", ref, profile)
    folder = art.save(tmp_path / "flip")
    task = backflip_task(folder)
    assert str(folder) in task.description and "built-in" in BACKFLIP.description
    (term,) = [t for t in task.rewards if t.name == "pose_deviation"]
    poses = bt.desired_joint_poses(term.params["source"])
    expected = ref.q[:, knee].reshape(5, 2).mean(axis=1)
    np.testing.assert_allclose(poses[:, knee - 7].numpy(), expected, atol=1e-6)
    with pytest.raises(ValueError, match="not an oracle artifact"):
        backflip_task(tmp_path / "missing")


def test_two_training_iterations_and_eval_with_task_metrics(tmp_path) -> None:
    assert get_task("backflip") is BACKFLIP
    result = train(tiny_config(tmp_path, "a2cf", task="backflip"), verbose=False)
    assert result.iterations_done == 2
    report = evaluate(result.run_dir, EvalConfig(num_envs=2, num_steps=10))
    metrics = report["task_metrics"]
    assert set(metrics["reached_phase_fraction"]) == set(bt.BACKFLIP_PHASES)
    assert metrics["reached_phase_fraction"]["stand"] == 1.0
    assert 0.0 <= metrics["success_rate"] <= 1.0
    assert (result.run_dir / "eval_backflip.png").is_file()


def test_env_state_round_trip_continues_the_fsm_exactly() -> None:
    task = dataclasses.replace(BACKFLIP, commands=bt.StartCommandConfig(delay_range_s=(0.0, 0.1)))
    first, second = make_env(task, 3, num_threads=1), make_env(task, 3, num_threads=1, seed=7)
    try:
        gen = torch.Generator().manual_seed(0)
        for _ in range(8):
            first.step(0.3 * torch.randn(3, 35, generator=gen))
        second.load_state_dict(first.state_dict())
        for _ in range(4):
            actions = 0.3 * torch.randn(3, 35, generator=gen)
            obs_a, rew_a, done_a, _ = first.step(actions)
            obs_b, rew_b, done_b, _ = second.step(actions)
            assert torch.equal(rew_a, rew_b) and torch.equal(done_a, done_b)
            assert torch.equal(obs_a["critic"], obs_b["critic"])
            assert torch.equal(first.phase, second.phase)
        assert (first.phase_machine.max_phase >= bt.CROUCH).all()  # the FSM did move
    finally:
        first.close()
        second.close()
