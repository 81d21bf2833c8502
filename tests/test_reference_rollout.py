"""Whole-clip rollouts (:mod:`rl.evaluation.reference_rollout`): the traces start on the clip's first frame
and line up with the oracle artifact's reference, the coach's wrench is applied as asked within
eta0, tasks without a clip reference are refused by name, and the reference played through the
joint PD alone falls within the built-in dance (what ``optimisation_vs_rl.ipynb`` shows)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optimal_control.oracle import OracleConfig, solve_dance
from rl.envs.config import EnvConfig
from rl.envs.vec_env import G1VecEnv
from rl.evaluation.reference_rollout import (
    ReferenceRolloutConfig,
    build_env,
    coach_assist,
    reference_motion,
    rollout_reference,
)
from rl.tasks.dance.task import dance_task
from rl.tasks.registry import get_task
from robots import g1
from robots.conventions import pin_to_mj_qpos

ROBOTS = ReferenceRolloutConfig(num_envs=3)
# the oracle at its quickest (tests/test_faults.py): one alpha, no video
QUICK_ORACLE = OracleConfig(alphas=(1.0,), novice_alpha=1.0, video=False, progress=False)


def _elbow_wave_csv(folder, q_stand: np.ndarray, rows: int):
    """A 30 fps clip: the standing pose with the right elbow waving 0.3 rad (~0.02 rad per 50 Hz
    frame, so a trace one frame off its reference shows)."""
    q = np.tile(q_stand, (rows, 1))
    q[:, 7 + g1.JOINT_NAMES.index("right_elbow_joint")] += 0.3 * np.sin(np.arange(rows) / 5)
    path = folder / f"elbow_{rows}.csv"
    np.savetxt(path, q, delimiter=",")
    return path


@pytest.fixture(scope="module")
def clip(tmp_path_factory, g1_pin):
    """0.8 s of elbow wave (41 frames at 50 Hz): short enough that no robot falls."""
    return _elbow_wave_csv(tmp_path_factory.mktemp("clip"), g1_pin.q_stand, rows=25)


@pytest.fixture(scope="module")
def oracle(clip, tmp_path_factory):
    """(artifact, folder) of ``solve-dance --clip`` on the clip (~1 s)."""
    out = tmp_path_factory.mktemp("oracle") / "dance"
    return solve_dance(cfg=dataclasses.replace(QUICK_ORACLE, out=str(out)), clip=str(clip))


@pytest.fixture(scope="module")
def clip_env(clip):
    """The dance env on the clip, along whole clips, on three randomised robots."""
    env = build_env(dance_task((clip,)), cfg=ROBOTS)
    yield env
    env.close()


@pytest.fixture(scope="module")
def pd_rollout(clip_env):
    """The reference through the joint PD, no help; with the clip time each step started from."""
    start_times_s = []

    def motion(env, obs):
        start_times_s.append(env.command_gen.reference_time_s().clone().numpy())
        return reference_motion(env, obs)

    return rollout_reference(clip_env, motion, label="reference PD"), np.asarray(start_times_s)


def test_traces_start_on_the_first_frame_and_follow_the_oracle_reference(pd_rollout, oracle):
    rollout, start_times_s = pd_rollout
    art, _ = oracle
    frames = art.reference.num_frames
    steps = frames - 1  # from frame 0 to the clip's last frame
    assert len(rollout.time_s) == steps, "the episode lasts the whole clip"
    assert rollout.joint_pos_rad.shape == rollout.ref_joint_pos_rad.shape == (steps, 3, 29)
    assert (start_times_s[0] == 0.0).all(), "every robot starts on the clip's first frame"
    # step k starts where step k - 1 ended: the clip time of the state after it is time_s[k - 1]
    alive = rollout.alive[:-1]
    np.testing.assert_allclose(
        start_times_s[1:][alive], np.broadcast_to(rollout.time_s[:-1, None], alive.shape)[alive]
    )
    np.testing.assert_allclose(rollout.time_s, art.reference.time_s[1:], atol=1e-9)
    # the recorded reference of step k is the artifact's frame k + 1, on every robot
    ref_joints = pin_to_mj_qpos(art.reference.q)[1:, 7:]  # (T, 29), JOINT_NAMES order
    np.testing.assert_allclose(
        rollout.ref_joint_pos_rad, np.broadcast_to(ref_joints[:, None], (steps, 3, 29)), atol=1e-6
    )
    # nobody falls in 0.8 s of standing; the last step times out and starts the next episode
    assert rollout.alive[:-1].all() and not rollout.alive[-1].any()
    assert rollout.metrics["survival_fraction"] == 1.0 and rollout.metrics["fell_fraction"] == 0.0
    assert np.all(rollout.applied_wrench == 0.0), "no assist: no wrench"
    t, q = rollout.joint("right_elbow_joint", env=1)
    assert len(t) == len(q) == steps - 1


def test_errors_from_the_traces_are_the_evaluators(pd_rollout):
    rollout, _ = pd_rollout
    errors = rollout.error_per_part_rad()
    assert set(errors) == {*g1.BODY_PARTS, "all"}
    for part, error in errors.items():
        assert error == pytest.approx(rollout.metrics[f"joint_{part}_rad"], rel=1e-5), part
    assert 0.0 < errors["all"] < 0.5


def test_the_coach_is_applied_as_asked_within_eta0(clip_env, oracle, pd_rollout):
    art, folder = oracle
    coach = coach_assist(folder)
    asked = []

    def assist(env):
        wrench = coach(env)
        asked.append(wrench.clone().numpy())
        return wrench

    helped = rollout_reference(clip_env, reference_motion, assist, art.eta0, "reference PD + coach")
    bound = art.eta0[0]  # the clip's one phase
    alive = helped.alive
    applied = helped.applied_wrench[alive]
    assert np.all(np.abs(applied) <= bound + 1e-4), "the wrench stays within eta0"
    np.testing.assert_allclose(
        applied, np.clip(np.asarray(asked)[alive], -0.999 * bound, 0.999 * bound), atol=1e-3
    )
    assert np.abs(applied).max() > 0.1 * bound.min(), "the coach acts"
    # the same robots along the same reference
    np.testing.assert_array_equal(helped.ref_joint_pos_rad, pd_rollout[0].ref_joint_pos_rad)
    with pytest.raises(ValueError, match="assist needs its bound"):
        rollout_reference(clip_env, reference_motion, assist)


def test_tasks_without_a_clip_reference_are_refused_by_name(clip):
    with pytest.raises(ValueError, match="task 'stand' does not track clips"):
        build_env(get_task("stand"), cfg=ROBOTS)
    one_robot = EnvConfig(num_envs=1, num_threads=1)
    stand = G1VecEnv(one_robot, get_task("stand"))
    try:
        with pytest.raises(ValueError, match="task 'stand' has no time-indexed joint reference"):
            rollout_reference(stand, reference_motion)
    finally:
        stand.close()
    # a dance env of its own starts its episodes anywhere along the clip: refused, not misaligned
    task = dance_task((clip,))
    task = dataclasses.replace(task, commands=dataclasses.replace(task.commands, min_frames_left=1))
    random_starts = G1VecEnv(dataclasses.replace(one_robot, num_envs=4, seed=3), task)
    try:
        with pytest.raises(ValueError, match="do not start on the reference's first frame"):
            rollout_reference(random_starts, reference_motion)
    finally:
        random_starts.close()


def test_the_reference_alone_falls_within_the_built_in_dance():
    """The notebook's point: the joint PD alone cannot keep the G1 up along the dance (it falls
    within ~2 s, as from the standing pose: docs/oracle.md)."""
    env = build_env(get_task("dance-joints"), cfg=dataclasses.replace(ROBOTS, num_envs=4))
    try:
        rollout = rollout_reference(env, reference_motion, label="reference PD")
        clip_steps = env.max_episode_length
    finally:
        env.close()
    assert rollout.metrics["survival_fraction"] < 0.5, rollout.metrics
    assert rollout.metrics["fell_fraction"] == 1.0 - rollout.metrics["survival_fraction"]
    # a robot's traces end at its fall and do not come back (the next episode is not its own)
    assert np.all(np.diff(rollout.alive.astype(int), axis=0) <= 0)
    up_steps = rollout.alive.sum(axis=0)
    assert np.median(up_steps) < clip_steps / 2
    t, _ = rollout.joint("left_knee_joint", env=int(np.argmin(up_steps)))
    assert len(t) == up_steps.min() and t[-1] < rollout.time_s[-1] <= clip_steps * env.step_dt_s


def test_the_episode_lasts_the_clip_whatever_its_length(tmp_path, g1_pin):
    clip = _elbow_wave_csv(tmp_path, g1_pin.q_stand, rows=35)  # 57 frames at 50 Hz
    env = build_env(dance_task((clip,)), cfg=dataclasses.replace(ROBOTS, num_envs=1))
    frames, steps = int(env.command_gen.library.length.max()), env.max_episode_length
    env.close()
    assert frames == 57
    assert steps == frames - 1
