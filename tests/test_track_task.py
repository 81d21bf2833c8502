"""The tracking task: the env's link sensors agree with the reference's kinematics, the rewards
peak on the reference and are blind to a shifted or turned origin, episodes end at the
reference's end without failing, adaptive start sampling, evaluation from the first frame, a
statue fails the skill measure, and references reach the trainer from the CLI config."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from optimal_control.reference_sources import parse_frames
from rl.envs.task_schema import quiet
from rl.tasks.registry import get_task, make_env, with_references
from rl.tasks.track import terms
from rl.tasks.track.task import TRACK, track_task
from rl.tasks.track.terms import ANCHOR, yaw_quat

ARMS = [15, 22]  # the joints the wave clip moves: left and right shoulder pitch


@pytest.fixture(scope="module")
def wave_clip(tmp_path_factory, g1_pin) -> str:
    """A 2 s, 50 fps NPZ clip of the stand pose with both arms waving and a small knee bend."""
    frames = 100
    t = np.arange(frames) / 50.0
    q = np.tile(g1_pin.q_stand, (frames, 1))
    q[:, 7 + 15] += 0.6 * np.sin(2 * np.pi * 0.5 * t)  # left shoulder pitch
    q[:, 7 + 22] += 0.6 * np.sin(2 * np.pi * 0.5 * t)  # right shoulder pitch
    path = tmp_path_factory.mktemp("clips") / "wave.npz"
    np.savez(path, qpos=q, fps=50.0)
    return str(path)


@pytest.fixture(scope="module")
def env(wave_clip):
    env = make_env(quiet(track_task((wave_clip,))), 4, num_threads=1)
    yield env
    env.close()


def zero_action_joint_error(env, steps: int, joints) -> float:
    """Mean |q - q_ref| [rad] over ``joints`` of the 2 robots of ``env`` at zero action."""
    errors = []
    for _ in range(steps):
        env.step(torch.zeros(2, 35))
        s = env.env_state
        errors.append(float((s.joint_pos_rad - s.targets["joint_pos_rad"])[:, joints].abs().mean()))
    return float(np.mean(errors))


def neutral_sim2sim(env, task, folder, steps: int) -> tuple[dict, list[np.ndarray]]:
    """Export a zero-action policy of ``env`` into ``folder`` and roll it out in sim2sim (2
    robots, seed 1): its bundle and the policy observation of every step."""
    from test_sim2sim import export_neutral_policy

    from rl.evaluation.sim2sim import Sim2SimConfig, run_sim2sim

    folder.mkdir()
    bundle = export_neutral_policy(env, folder)
    seen: list[np.ndarray] = []
    run_sim2sim(folder, task, steps, Sim2SimConfig(num_envs=2, seed=1), on_step=seen.append)
    return bundle, seen


def _on_reference(env, ahead: int = 1):
    """Put every robot exactly on the frame its command targets (with its floor offset)."""
    cmd, lay = env.command_gen, env.layout
    frames = cmd.frame(ahead=ahead).numpy()
    qpos = cmd.library.qpos[frames].copy()
    qpos[:, 2] += cmd.z_offset_m.numpy()
    env.state[:, lay.qpos] = qpos
    env.state[:, lay.qvel] = cmd.library.qvel[frames]
    env.physics.refresh_sensors(torch.arange(env.num_envs))
    return env._read_state()


def test_link_sensors_match_the_reference_kinematics(env) -> None:
    s = _on_reference(env)
    for key in ("body_pos_w", "body_quat_w", "body_lin_vel_w", "body_ang_vel_w"):
        torch.testing.assert_close(s.__dict__[key], s.targets[key], atol=1e-4, rtol=0), key
    for term in env.task.rewards[:6]:
        torch.testing.assert_close(term(s), torch.ones(env.num_envs), atol=1e-4, rtol=0)
    assert not any(t(s).any() for t in env.task.terminations)
    # one frame off (the current frame, not the target), the link errors are not zero
    off = _on_reference(env, ahead=0)
    off.targets = s.targets
    assert (terms.body_linear_velocity(off) < 1.0).all() or (terms.body_position(off) < 1.0).all()


def test_relative_body_rewards_ignore_a_shifted_and_turned_origin(env) -> None:
    s = _on_reference(env)
    yaw = torch.full((env.num_envs,), 0.7)
    rot = yaw_quat(yaw)
    shifted = dict(s.targets)
    pos = s.targets["body_pos_w"] - s.targets["body_pos_w"][:, ANCHOR : ANCHOR + 1]
    n, k = pos.shape[:2]
    from rl.envs.state import quat_multiply, quat_rotate

    turned = quat_rotate(rot.repeat_interleave(k, 0), pos.reshape(-1, 3)).reshape(n, k, 3)
    shifted["body_pos_w"] = (
        turned + torch.tensor([1.5, -2.0, 0.0]) + s.targets["body_pos_w"][:, ANCHOR : ANCHOR + 1]
    )
    shifted["body_quat_w"] = quat_multiply(
        rot.repeat_interleave(k, 0), s.targets["body_quat_w"].reshape(-1, 4)
    ).reshape(n, k, 4)
    moved = dataclasses.replace(s, targets=shifted)
    torch.testing.assert_close(terms.body_position(moved), torch.ones(n), atol=1e-4, rtol=0)
    torch.testing.assert_close(terms.body_orientation(moved), torch.ones(n), atol=1e-4, rtol=0)
    # the global anchor terms do see it
    assert (terms.anchor_position(moved) < 0.01).all()
    assert (terms.anchor_orientation(moved) < 0.2).all()


def test_drift_terminations_fire_past_their_thresholds(env) -> None:
    s = _on_reference(env)
    lifted = dict(s.targets)
    lifted["body_pos_w"] = s.targets["body_pos_w"] + torch.tensor([0.0, 0.0, 0.3])
    moved = dataclasses.replace(s, targets=lifted)
    assert terms.anchor_height_drift(moved).all()
    assert terms.end_effector_height_drift(moved).all()
    assert not terms.anchor_tilt_drift(moved).any()
    # drift-free phases: the same drift ends no episode of an env in one of them
    phase = torch.arange(s.phase.shape[0]) % 2
    split = dataclasses.replace(moved, phase=phase)
    assert torch.equal(terms.end_effector_height_drift(split, free_phases=(1,)), phase == 0)
    flipped = dict(s.targets)
    flipped["body_quat_w"] = torch.tensor([0.0, 0.0, 1.0, 0.0]).expand_as(s.targets["body_quat_w"])
    tilted = dataclasses.replace(s, targets=flipped, phase=phase)
    assert terms.anchor_tilt_drift(tilted).all()
    assert torch.equal(terms.anchor_tilt_drift(tilted, free_phases=(1,)), phase == 0)


def test_drift_free_phases_reach_the_terms_by_name() -> None:
    """--task-drift-free-phases names phases; the tracking task turns them into the drift terms'
    phase indices once its phases are read from the reference; unknown names and tasks without
    drift terminations are refused."""
    from rl.tasks.track.phases import ReferencePhaseConfig
    from rl.tasks.track.task import with_drift_free_phases

    task = dataclasses.replace(
        get_task("track"),
        phases=ReferencePhaseConfig(names=("stand", "jump", "air", "land")),
        assist_bound=get_task("track").assist_bound * 4,
        drift_free_phases=("jump", "air"),
    )
    free = {t.name: t.params.get("free_phases") for t in with_drift_free_phases(task).terminations}
    assert free == {"anchor_height": None, "anchor_tilt": (1, 2), "end_effector_height": (1, 2)}
    with pytest.raises(ValueError, match="has no such phase; its phases: stand jump air land"):
        with_drift_free_phases(dataclasses.replace(task, drift_free_phases=("fly",)))
    with pytest.raises(ValueError, match="no drift termination to switch off"):
        get_task("walk-flat").with_overrides({"drift_free_phases": ["air"]})


def test_episodes_end_at_the_reference_end_as_time_outs(wave_clip) -> None:
    env = make_env(quiet(track_task((wave_clip,))), 2, num_threads=1)
    try:
        cmd = env.command_gen
        cmd.for_evaluation()
        env.reset_envs(torch.arange(2))
        assert (cmd.frame(0) == cmd._start[cmd.clip]).all()  # evaluation: from the first frame
        actions = torch.zeros(2, 35)
        ends = []
        for step in range(int(cmd.library.length[0]) + 5):
            _on_reference(env, ahead=0)  # held on the reference: no drift ends it early
            actions[:, :29] = env.joint_targets_to_actions(cmd.reference_joint_pos_rad())
            _, _, dones, extras = env.step(actions)
            if dones.any():
                ends.append((step, extras["time_outs"].clone(), env.env_state.terminated.clone()))
                break
        step, time_outs, _ = ends[0]
        assert step == int(cmd.library.length[0]) - 2  # the step that reached the last frame
        assert time_outs.all()
    finally:
        env.close()


def test_adaptive_sampling_follows_failures(env) -> None:
    cmd = env.command_gen
    probs = cmd.sampling_probabilities()
    torch.testing.assert_close(probs, torch.full_like(probs, 1 / probs.numel()))
    saved = cmd.failures.clone()
    try:
        cmd.failures[:] = 0
        cmd.failures[1] = 1.0
        probs = cmd.sampling_probabilities()
        assert probs[1] > probs[0] > probs[-1] if probs.numel() > 2 else probs[1] > probs[0]
        torch.testing.assert_close(probs.sum(), torch.tensor(1.0, dtype=probs.dtype))
    finally:
        cmd.failures[:] = saved


def test_failures_are_counted_in_the_bin_where_episodes_fell(wave_clip) -> None:
    env = make_env(quiet(track_task((wave_clip,))), 4, num_threads=1)
    try:
        cmd = env.command_gen
        assert cmd.failures.sum() == 0
        actions = torch.zeros(4, 35)
        actions[:, :29] = 3.0  # joint targets far off: the robots fall
        for _ in range(150):
            env.step(actions)
        assert cmd.failures.sum() > 0
        state = env.state_dict()["task_components"]["command_gen"]
        assert torch.equal(state["failures"], cmd.failures)
    finally:
        env.close()


def test_a_statue_fails_the_skill_measure(wave_clip) -> None:
    """Holding the standing pose survives the gentle clip but does not track it."""
    from rl.evaluation.alone import rollout_alone

    env = make_env(quiet(track_task((wave_clip,))), 2, num_threads=1)
    try:
        stand = env.joint_targets_to_actions(env.motion.stand_rad.expand(2, 29))
        result = rollout_alone(env, lambda obs: stand)
    finally:
        env.close()
    metrics = result["task_metrics"]
    assert metrics["statue_joint_error_rad"] > 0.02  # 2 joints of 29 waving 0.6 rad: 0.026
    assert metrics["statue_ratio"] > 0.5  # a statue is (about) the statue
    assert metrics["tracking_score"] > 1.0
    assert not result["target_reached"]
    assert set(metrics["per_reference"]) == {wave_clip}


def test_references_reach_the_task_and_bad_ones_are_refused(wave_clip) -> None:
    task = with_references(get_task("track"), (wave_clip,), "0:80")
    assert task.commands.sources == (wave_clip,) and task.commands.frames == "0:80"
    assert with_references(TRACK, (), "") is TRACK
    with pytest.raises(ValueError, match="takes no --reference"):
        with_references(get_task("stand"), (wave_clip,), "")
    for text in ("0-600", "a:b", "5:5", "-1:3"):
        with pytest.raises(ValueError, match="--reference-frames"):
            parse_frames(text)
    assert parse_frames("") is None and parse_frames("10:20") == (10, 20)


def test_a_reference_shorter_than_a_second_is_refused(wave_clip) -> None:
    with pytest.raises(ValueError, match="shorter than 1 s"):
        make_env(quiet(track_task((wave_clip,), frames="0:40")), 1, num_threads=1)


def test_dance_is_track_on_the_built_in_choreography() -> None:
    dance = get_task("dance")
    assert dance.commands.sources == ("builtin",)
    assert {t.name for t in dance.rewards} == {t.name for t in TRACK.rewards}
    assert dance.target.metric == "tracking_score" and math.isclose(dance.target.max_metric, 1.0)


def test_a_warm_start_must_come_from_the_tracked_motion(wave_clip, tmp_path) -> None:
    from optimal_control.oracle import OracleConfig, solve_reference_oracle
    from optimal_control.reference_sources import load_reference
    from rl.a2cf.warmstart import warmstart_eta0
    from rl.training.config import TrainConfig

    cfg = OracleConfig(alphas=(1.0,), video=False, progress=False, out=str(tmp_path / "wave"))
    _, folder = solve_reference_oracle("dance", load_reference(wave_clip), cfg, {})
    train = TrainConfig(warmstart=str(folder))
    eta0 = warmstart_eta0(train, track_task((wave_clip,)))  # task 'track', artifact 'dance'
    assert eta0 is not None and eta0.shape == (1, 6)
    assert warmstart_eta0(train, track_task((str(folder),))) is not None  # the artifact itself
    with pytest.raises(ValueError, match="solved on another motion"):
        warmstart_eta0(train, track_task((wave_clip,), frames="0:60"))  # a segment: not the same


def test_cli_trains_evaluates_and_exports_a_csv_segment(tmp_path, g1_pin, capsys) -> None:
    """``train --task track --reference CLIP.csv --reference-frames A:B``, then ``eval``; a bad
    reference gets one line naming it, before any run folder is made."""
    import json

    from a2cf_mb.cli import main

    t = np.arange(90) / 30.0  # 3 s at 30 fps, the LAFAN1 CSV layout (Pinocchio's q)
    rows = np.tile(g1_pin.q_stand, (t.size, 1))
    rows[:, 7 + 15] += 0.5 * np.sin(2 * np.pi * 0.5 * t)  # left shoulder pitch
    csv = tmp_path / "wave.csv"
    np.savetxt(csv, rows, delimiter=",")
    common = ["--num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1",
              "--eval-interval", "0", "--out", str(tmp_path / "runs")]  # fmt: skip
    assert main(["train", "--task", "track", "--reference", str(csv), "--reference-frames",
                 "0:60", "--run-name", "wave", *common]) == 0  # fmt: skip
    run = tmp_path / "runs" / "wave"
    assert (run / "policy.onnx").is_file()
    saved = json.loads((run / "config.json").read_text())["train"]
    assert saved["reference"] == [str(csv)] and saved["reference_frames"] == "0:60"
    assert main(["eval", str(run), "--num-envs", "2"]) == 0
    metrics = json.loads((run / "eval.json").read_text())["task_metrics"]
    assert set(metrics["per_reference"]) == {str(csv)}
    assert metrics["statue_joint_error_rad"] > 0.0 and "tracking_score" in metrics
    capsys.readouterr()
    bad = np.c_[rows[:, :7], np.degrees(rows[:, 7:])]
    np.savetxt(tmp_path / "degrees.csv", bad, delimiter=",")
    for reference, needle in ((tmp_path / "missing.csv", "does not exist"),
                              (tmp_path / "degrees.csv", "degrees")):  # fmt: skip
        assert main(["train", "--task", "track", "--reference", str(reference),
                     "--run-name", "bad", *common]) == 2  # fmt: skip
        err = capsys.readouterr().err
        assert needle in err and str(reference) in err and "Traceback" not in err
        assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "runs" / "bad").exists()


def test_an_artifact_on_a_finer_grid_is_tracked_at_the_policy_rate(wave_clip, tmp_path) -> None:
    """A backflip-like artifact (its TO's 200 Hz grid) is resampled to the 50 Hz policy step, and
    its warm start still recognises the tracked motion as its own."""
    from optimal_control.oracle import OracleConfig, solve_reference_oracle
    from optimal_control.reference_sources import load_reference
    from rl.a2cf.warmstart import warmstart_eta0
    from rl.tasks.track.library import at_policy_rate, load_track_reference
    from rl.training.config import TrainConfig

    clip = load_reference(wave_clip)
    fine = at_policy_rate(clip, 0.005)
    assert fine.num_frames == 4 * (clip.num_frames - 1) + 1
    cfg = OracleConfig(alphas=(1.0,), video=False, progress=False, out=str(tmp_path / "fine"))
    _, folder = solve_reference_oracle("dance", fine, cfg, {})
    tracked = load_track_reference(str(folder), None, 0.02)
    assert tracked.dt == 0.02 and tracked.num_frames == clip.num_frames
    np.testing.assert_allclose(tracked.q, clip.q, atol=1e-6)  # the 50 Hz frames come back
    env = make_env(quiet(track_task((str(folder),))), 1, num_threads=1)
    try:
        assert int(env.command_gen.library.length[0]) == clip.num_frames
    finally:
        env.close()
    assert (
        warmstart_eta0(TrainConfig(warmstart=str(folder)), track_task((str(folder),))) is not None
    )


@pytest.mark.parametrize("simulator", ["env", "sim2sim"])
def test_actions_around_the_reference_follow_it_at_zero_action(wave_clip, tmp_path, simulator):
    """``actions_around_reference``: PD targets q_ref + scale a, so zero action follows the waving
    shoulders, in the training env and in sim2sim from the bundle; around the standing pose it does
    not; a task without reference joints refuses the option."""
    from test_sim2sim import command_term

    def tracking_error(around: bool) -> float:
        task = dataclasses.replace(quiet(track_task((wave_clip,))), actions_around_reference=around)
        env = make_env(task, 2, num_threads=1)
        try:
            if simulator == "env":
                env.command_gen.for_evaluation()
                env.reset_envs(torch.arange(2))
                ref = env.command_gen.reference_joint_pos_rad()
                assert (
                    torch.allclose(env.joint_targets_to_actions(ref), torch.zeros(2, 29)) == around
                )
                return zero_action_joint_error(env, 60, ARMS)
            bundle, seen = neutral_sim2sim(env, task, tmp_path / f"around_{around}", 60)
            assert ("action_base_command_columns" in bundle["control"]) == around
        finally:
            env.close()
        columns = {t["name"]: t["columns"] for t in bundle["observation"]["terms"]}
        start = command_term(bundle)["columns"][0]
        default = np.array([j["default_pos_rad"] for j in bundle["joints"]])
        # the joints seen at step k + 1 against the reference the command of step k targeted
        q = np.stack([o[:, slice(*columns["joint_pos"])] + default for o in seen[1:]])
        q_ref = np.stack([o[:, start : start + 29] for o in seen[:-1]])
        return float(np.abs(q - q_ref)[..., ARMS].mean())

    around, stand = tracking_error(True), tracking_error(False)
    assert around < 0.25 * stand, (around, stand)  # stand: the 0.6 rad wave, untracked
    with pytest.raises(ValueError, match="actions_around_reference needs a command"):
        make_env(dataclasses.replace(quiet(get_task("stand")), actions_around_reference=True), 1)
