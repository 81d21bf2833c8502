"""Tracking a flip: a reference that turns over is held standing at both ends, its phases drive the
env's phase (so eta0 and the curriculum work per phase), and the flip judge lands a robot that
follows the flip exactly while failing one that does not."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from test_track_task import _on_reference, neutral_sim2sim, zero_action_joint_error

from rl.envs.task_schema import quiet
from rl.evaluation.alone import rollout_alone
from rl.tasks.dance.clips import grounded_shift
from rl.tasks.registry import get_task, make_env, with_references
from rl.tasks.track.flip import FLIP_HOLD_S, FlipEvaluationConfig
from rl.tasks.track.library import hold_ends, pitch_turn_rad
from rl.tasks.track.phases import ReferencePhaseConfig

PHASES = ("stand", "air", "land")


@pytest.fixture(scope="module")
def flip_reference(g1_pin):
    """A 50 Hz backflip of the standing robot, rigid: 0.4 s standing, 0.7 s in the air (the pelvis
    rises 0.7 m and turns -2 pi about its pitch axis), 0.4 s standing again."""
    from optimal_control.motion_clip import reference_from_configurations

    dt, stand, air = 0.02, 20, 35
    frames = 2 * stand + air
    q = np.tile(g1_pin.q_stand, (frames, 1))
    u = np.clip((np.arange(frames) - stand) / air, 0.0, 1.0)
    pitch = -2 * math.pi * (3 * u**2 - 2 * u**3)
    q[:, 2] += 0.7 * 4 * u * (1 - u)
    q[:, 3:7] = np.stack(
        [np.zeros(frames), np.sin(pitch / 2), np.zeros(frames), np.cos(pitch / 2)], axis=1
    )
    contacts = np.repeat(((u <= 0) | (u >= 1))[:, None], 2, axis=1)
    phase = np.where(u <= 0, 0, np.where(u >= 1, 2, 1))
    phase[stand + air :] = 2
    ref = reference_from_configurations(q, dt, contacts=contacts, phase_names=PHASES)
    return dataclasses.replace(ref, phase=phase.astype(np.int64)).validate()


@pytest.fixture(scope="module")
def flip_artifact(flip_reference, tmp_path_factory) -> str:
    from optimal_control.oracle import OracleConfig, solve_reference_oracle

    out = tmp_path_factory.mktemp("flip") / "oracle"
    cfg = OracleConfig(alphas=(1.0,), video=False, progress=False, out=str(out))
    _, folder = solve_reference_oracle("backflip", flip_reference, cfg, {})
    return str(folder)


def test_held_ends_and_the_shift_of_frames_in_the_air(flip_reference) -> None:
    held = hold_ends(flip_reference, 0.5)
    assert held.num_frames == flip_reference.num_frames + 50
    np.testing.assert_allclose(held.q[:25], np.repeat(flip_reference.q[:1], 25, 0))
    assert not held.v[:25].any() and not held.v[-25:].any()
    assert (held.phase[:25] == 0).all() and (held.phase[-25:] == 2).all()
    assert hold_ends(flip_reference, 0.0) is flip_reference
    # a frame in the air is lowered as the ground frames beside it are, not onto the floor
    shift = np.array([0.0, 0.0, 0.5, 0.7, 0.5, 0.01])
    contacts = np.array([[1, 1], [1, 1], [0, 0], [0, 0], [0, 0], [1, 1]], dtype=bool)
    np.testing.assert_allclose(
        grounded_shift(shift, contacts), [0, 0, 0, 0, 0.01, 0.01]
    )  # a tie: the earlier
    np.testing.assert_allclose(grounded_shift(shift, np.ones((6, 2), bool)), shift)


def test_the_pitch_turn_of_a_flip_and_of_standing(flip_reference) -> None:
    quat = flip_reference.q[:, [6, 3, 4, 5]]
    assert pitch_turn_rad(quat) == pytest.approx(-2 * math.pi, abs=1e-6)
    assert pitch_turn_rad(np.tile(quat[:1], (10, 1))) == pytest.approx(0.0, abs=1e-9)


def test_a_flip_artifact_sets_up_the_task_and_drives_its_phases(flip_artifact) -> None:
    task = with_references(get_task("track"), (flip_artifact,), "")
    assert isinstance(task.phases, ReferencePhaseConfig) and task.phase_names == PHASES
    assert len(task.assist_bound) == 3 and task.commands.hold_s == FLIP_HOLD_S
    assert isinstance(task.evaluation, FlipEvaluationConfig) and task.evaluation.direction == -1
    assert task.target.metric == "flips_failed"
    env = make_env(quiet(task), 2, num_threads=1)
    try:
        cmd, lib = env.command_gen, env.command_gen.motion
        assert lib.hold_frames == round(FLIP_HOLD_S / 0.02)
        cmd.for_evaluation()
        env.reset_envs(torch.arange(2))
        assert float(cmd.reference_time_s()[0]) == pytest.approx(-FLIP_HOLD_S)
        seen = set()
        for _ in range(int(lib.clips.length[0]) - 2):
            _on_reference(env, ahead=0)
            actions = torch.zeros(2, 35)
            actions[:, :29] = env.joint_targets_to_actions(cmd.reference_joint_pos_rad())
            _, _, dones, _ = env.step(actions)
            if dones.any():
                break
            assert torch.equal(env.phase, lib.phase[cmd.frame(ahead=1)])  # the target frame's
            seen.update(env.phase.tolist())
        assert seen == {0, 1, 2}
    finally:
        env.close()
    # the stand task has no reference: its single phase stays
    assert with_references(get_task("track"), (), "") is get_task("track")


def test_the_flip_judge_lands_the_reference_and_fails_a_statue(flip_artifact) -> None:
    task = quiet(with_references(get_task("track"), (flip_artifact,), ""))
    env, still = make_env(task, 2, num_threads=1), make_env(task, 2, num_threads=1)
    try:

        def follower(obs):  # put the robot exactly on the reference, then aim at the next frame
            _on_reference(env, ahead=0)
            return env.joint_targets_to_actions(env.command_gen.reference_joint_pos_rad())

        follows = rollout_alone(env, follower)["task_metrics"]
        stand = still.joint_targets_to_actions(still.motion.stand_rad.expand(2, 29))
        statue = rollout_alone(still, lambda obs: stand)["task_metrics"]
    finally:
        env.close()
        still.close()
    assert follows["turn_rad_mean"] == pytest.approx(2 * math.pi, abs=0.3)
    assert follows["flips_landed"] == 1.0 and follows["flips_failed"] == 0.0
    assert follows["phase_reached"]["land"] == 1.0
    assert statue["flips_landed"] == 0.0 and statue["full_turns"] == 0.0
    assert statue["phase_reached"]["land"] < 1.0 or statue["upright_still_at_end"] == 1.0


# --------------------------------------------------------------------------- mode coach (ZEST)
def test_the_coach_scale_follows_the_failure_rate() -> None:
    from rl.a2cf.config import CoachHelpConfig

    cfg = CoachHelpConfig(source="x")
    assert cfg.scale(1.0) == pytest.approx(0.6)  # failing: the most help
    assert cfg.scale(0.6) == pytest.approx(0.5)
    assert cfg.scale(0.2) == 0.0 and cfg.scale(0.0) == 0.0  # help ends at 20 % failures
    with pytest.raises(ValueError, match="--coach-failure-floor"):
        CoachHelpConfig(failure_floor=1.0)


def test_mode_coach_needs_its_source_and_nothing_else_takes_it() -> None:
    from rl.a2cf.config import CoachHelpConfig
    from rl.training.config import TrainConfig

    with pytest.raises(ValueError, match="--coach-source"):
        TrainConfig(mode="coach")
    with pytest.raises(ValueError, match="--coach-source"):
        TrainConfig(mode="a2cf", coach=CoachHelpConfig(source="somewhere"))


def test_mode_coach_applies_the_scaled_coach_and_resumes_exactly(flip_artifact, tmp_path) -> None:
    """The applied wrench is beta x the coach's; beta follows the failures of finished episodes
    (zero once they are rare); two iterations resumed to four equal four in one go."""
    from test_training import PLAIN_KEYS, TINY_MODEL, TINY_PPO

    from rl.a2cf.coach_help import CoachHelpEnv
    from rl.a2cf.config import CoachHelpConfig
    from rl.envs.config import EnvConfig
    from rl.training.config import TrainConfig
    from rl.training.runner import train

    task = quiet(with_references(get_task("track"), (flip_artifact,), ""))
    env = make_env(task, 4, num_threads=1)
    try:
        helped = CoachHelpEnv(env, CoachHelpConfig(source=flip_artifact))
        assert float(helped.beta[0]) == pytest.approx(0.6)  # no episode yet: failing
        pushed = 0.0
        for _ in range(40):  # the coach helps as needed: once the robots drift off the flip
            expected = helped.coach(env) * helped.beta.unsqueeze(-1)
            helped.step(torch.full((4, 29), 0.5))
            torch.testing.assert_close(env.applied_wrench, expected, atol=1e-3, rtol=1e-2)
            pushed += float(expected.abs().sum())
        assert pushed > 0
        helped.failures.push(torch.zeros(256))  # every recent episode succeeded
        helped.beta[:] = helped.coach_cfg.scale(helped.failure_rate())
        helped.step(torch.zeros(4, 29))
        assert env.applied_wrench.abs().sum() == 0
    finally:
        env.close()

    def config(name: str, iterations: int) -> TrainConfig:
        return TrainConfig(
            task="track", reference=(flip_artifact,), mode="coach",
            coach=CoachHelpConfig(source=flip_artifact, window=8), env=EnvConfig(num_envs=4),
            iterations=iterations, num_steps_per_env=16, out=str(tmp_path), run_name=name,
            save_interval=1, ppo=TINY_PPO, model=TINY_MODEL, export_onnx=False,
        )  # fmt: skip

    whole = train(config("whole", 4), verbose=False)
    part = train(config("part", 2), verbose=False)
    resumed = train(TrainConfig(resume=str(part.run_dir), iterations=4), verbose=False)
    a, b = whole.metrics["iterations"], resumed.metrics["iterations"]
    for row_a, row_b in zip(a, b, strict=True):
        assert {k: row_a[k] for k in PLAIN_KEYS} == {k: row_b[k] for k in PLAIN_KEYS}


# ------------------------------------------------------------------- the oracle's feed-forward
@pytest.mark.parametrize("simulator", ["env", "sim2sim"])
def test_the_oracle_feedforward_holds_the_robot_up_at_zero_action(
    flip_artifact, tmp_path, simulator
) -> None:
    """``action_feedforward``: the artifact's planned torques (its QP's at alpha 1 here) ride along
    the tracking library (held ends: the end frames'), the PD targets shift by
    kd/kp qd_ref + tau_ref/kp, and at zero action over the held standing second the legs sag less
    than under the PD alone, in the env and in sim2sim from the bundle. Without actions around
    the reference the option is refused."""

    from optimal_control.artifact import OracleArtifact
    from robots import g1

    task = quiet(with_references(get_task("track"), (flip_artifact,), ""))
    legs = slice(0, 12)

    def sag(feedforward: bool) -> float:
        t = dataclasses.replace(task, action_feedforward=feedforward)
        env = make_env(t, 2, num_threads=1)
        try:
            lib, cmd = env.command_gen.motion, env.command_gen
            planned = OracleArtifact.load(flip_artifact).profiles[1.0].tau_nm
            held = lib.hold_frames
            np.testing.assert_allclose(
                lib.joint_torque_nm[held : held + len(planned)].numpy(), planned, atol=1e-3
            )
            np.testing.assert_allclose(
                lib.joint_torque_nm[:held].numpy(), planned[:1].repeat(held, 0), atol=1e-3
            )
            cmd.for_evaluation()
            env.reset_envs(torch.arange(2))
            qd, tau = cmd.reference_joint_feedforward()
            shift = env._action_base() - cmd.reference_joint_pos_rad()
            expected = (qd * torch.as_tensor(g1.KD / g1.KP) + tau / torch.as_tensor(g1.KP)).float()
            torch.testing.assert_close(shift, expected if feedforward else torch.zeros_like(shift))
            if simulator == "env":
                return zero_action_joint_error(env, 25, legs)
            bundle, seen = neutral_sim2sim(env, t, tmp_path / f"ff_{feedforward}", 25)
            assert ("action_feedforward" in bundle["control"]) == feedforward
        finally:
            env.close()
        columns = {term["name"]: term["columns"] for term in bundle["observation"]["terms"]}
        # the standing second's reference is the stand pose: the legs' offsets from it
        return float(
            np.mean([np.abs(o[:, slice(*columns["joint_pos"])][:, legs]).mean() for o in seen[1:]])
        )

    with_ff, without = sag(True), sag(False)
    assert with_ff < 0.7 * without, (with_ff, without)
    with pytest.raises(ValueError, match="action_feedforward shifts the PD targets"):
        make_env(
            dataclasses.replace(task, actions_around_reference=False, action_feedforward=True), 1
        )


def test_the_judge_allows_the_links_the_reference_puts_down(flip_artifact) -> None:
    """A link on the ground fails a flip only where the reference keeps it off: the library
    finds the links a pose puts down (a robot sunk into the floor: shins and more; standing:
    none), and the command dilates the reference's contacts by the judge's margin."""
    from rl.tasks.track.library import link_ground_contacts

    task = quiet(with_references(get_task("track"), (flip_artifact,), ""))
    env = make_env(task, 2, num_threads=1)
    try:
        cmd, lib = env.command_gen, env.command_gen.motion
        assert not lib.link_ground_contact.any()  # the synthetic flip stays on its soles
        names = env.env_state.contact_body_names
        assert lib.contact_bodies == names
        stand = lib.clips.qpos[:1].copy()
        sunk = stand.copy()
        sunk[:, 2] -= 0.45
        down, bodies = link_ground_contacts(np.concatenate([stand, sunk]))
        assert not down[0].any() and down[1, bodies.index("left_knee_link")]
        kept = lib.link_ground_contact.clone()  # the library is shared by the process's envs
        lib.link_ground_contact[:] = False
        lib.link_ground_contact[10, bodies.index("left_knee_link")] = True
        cmd.for_evaluation()
        env.reset_envs(torch.arange(2))
        seen = []
        for _ in range(16):
            seen.append(bool(cmd.reference_link_contact(("left_knee_link",), 3)[0, 0]))
            env.step(torch.zeros(2, 35))
        assert seen == [False] * 7 + [True] * 7 + [False] * 2  # frames 7..13: 10 +- 3
    finally:
        lib.link_ground_contact[:] = kept
        env.close()


def test_sim2sim_judges_flips_as_the_training_physics_does(flip_artifact, tmp_path) -> None:
    """sim2sim scores its rollouts with the task's flip judge too (``task_metrics``): a robot
    holding the reference's joints at zero action stands through the held start, tips over and
    is cut off when the reference leaps, at the same step in both simulators, with the same
    verdicts and nearly the same turn and tracking error."""
    from test_sim2sim import export_neutral_policy

    from rl.evaluation.sim2sim import Sim2SimConfig, run_sim2sim

    task = dataclasses.replace(
        quiet(with_references(get_task("track"), (flip_artifact,), "")),
        actions_around_reference=True,
    )
    env = make_env(task, 2, num_threads=1)
    try:
        export_neutral_policy(env, tmp_path)
        trained = rollout_alone(env, lambda obs: torch.zeros(2, 29))
        steps = int(env.max_episode_length)
    finally:
        env.close()
    other = run_sim2sim(tmp_path, task, steps, Sim2SimConfig(num_envs=2, seed=1))
    judged, ours = other["task_metrics"], trained["task_metrics"]
    assert judged["success_rate"] == other["survival_fraction"] == 0.0
    assert judged["flips_landed"] == ours["flips_landed"] == 0.0
    assert judged["phase_reached"] == ours["phase_reached"]
    # it tips over forwards (-0.76 rad here): the same turn, read from the sim2sim robots' pelvis
    assert ours["turn_rad_mean"] < -0.3
    assert abs(judged["turn_rad_mean"] - ours["turn_rad_mean"]) < 0.15
    assert abs(judged["joint_error_rad"] / ours["joint_error_rad"] - 1) < 0.2
    length = trained["mean_episode_length_steps"]
    assert 25 < length < steps - 25  # cut off along the leap, not at either end
    assert abs(other["mean_episode_length_steps"] - length) <= 3
    assert abs(judged["frames_scored"] - ours["frames_scored"]) <= 6
