"""Warm start: the as-needed posture coach, DAgger distillation of the assist head, --warmstart."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
import torch

from rl.a2cf.coaches import PostureCoach, PostureCoachConfig
from rl.a2cf.config import WarmStartConfig
from rl.a2cf.warmstart import distill_assist_head
from rl.envs.config import EnvConfig
from rl.envs.task_schema import quiet
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND
from rl.training.config import ModelConfig, PPOConfig, TrainConfig
from rl.training.runner import train

TINY_MODEL = ModelConfig(motion_hidden_dims=(32,), assist_hidden_dims=(32, 32),
                         critic_hidden_dims=(32,), encoder_hidden_dims=(32,), latent_dim=4)  # fmt: skip


def tilted_state(env, pitch_rad: float, drop_m: float = 0.0):
    """The env's state with the pelvis pitched forward by ``pitch_rad`` and lowered by ``drop_m``."""
    s = env.env_state
    q = torch.tensor([math.cos(pitch_rad / 2), 0.0, math.sin(pitch_rad / 2), 0.0])
    s.base_quat_w = q.expand(env.num_envs, 4).clone()
    s.base_pos_w = s.base_pos_w.clone()
    s.base_pos_w[:, 2] = 0.74 - drop_m
    s.base_ang_vel_b = torch.zeros(env.num_envs, 3)
    s.base_lin_vel_w = torch.zeros(env.num_envs, 3)
    s.assist_bound = torch.full((env.num_envs, 6), 1e4)
    return s


def test_posture_coach_helps_only_outside_its_band():
    env = make_env(quiet(STAND), 2, num_threads=1)
    coach = PostureCoach.for_env(env, PostureCoachConfig(tilt_band_rad=0.15, height_band_m=0.08))
    inside = coach(tilted_state(env, 0.1, drop_m=0.05))
    assert not inside.any()  # the learner is on its own inside the band
    out = coach(tilted_state(env, 0.35, drop_m=0.2))
    # pitched forward (about +y): the restoring torque is about -y; too low: pushed up
    assert (out[:, 4] < 0).all() and (out[:, 2] > 0).all()
    assert out[0, 4] == pytest.approx(-coach.kp_tilt * 0.2, rel=1e-3)
    assert out[0, 2] == pytest.approx(coach.kp_height * 0.12, rel=1e-3)
    # sized from mass and inertia: the tilt stiffness exceeds gravity's toppling stiffness m g h
    assert coach.kp_tilt > env.total_mass_kg * 9.81 * 0.5
    bounded = tilted_state(env, 0.6)
    bounded.assist_bound = torch.full((2, 6), 5.0)
    assert coach(bounded).abs().max() <= 5.0


def test_distilled_head_reproduces_the_coach_on_held_out_states():
    from rl.training.runner import build_training

    cfg = TrainConfig(mode="a2cf", env=EnvConfig(num_envs=24, num_threads=2), model=TINY_MODEL,
                      ppo=PPOConfig(num_mini_batches=2))  # fmt: skip
    env, runner, _ = build_training(cfg, run_dir=None)
    posture = PostureCoach.for_env(env)
    report = distill_assist_head(runner.alg.actor, env, lambda e: posture(e.env_state),
                                 WarmStartConfig(rounds=2, steps_per_round=32, epochs=15))  # fmt: skip
    fit = report["held_out_fit"]
    assert report["share_of_states_helped"] > 0.1
    for axis in ("mx", "my"):  # the balance torques, heading frame
        assert fit[axis]["r2"] > 0.3, fit[axis]
    assert fit["fx"]["coach_mean_abs"] == 0.0 and fit["fx"]["head_mean_abs"] < 1.0
    std = runner.alg.actor.distribution.std_param.detach()
    torch.testing.assert_close(std[29:], torch.full((6,), 0.3))
    env.close()


def test_train_with_warmstart_writes_the_report_and_refuses_bad_sources(tmp_path):
    cfg = TrainConfig(mode="a2cf", warmstart="posture", iterations=1, num_steps_per_env=8,
                      env=EnvConfig(num_envs=4, num_threads=2), model=TINY_MODEL,
                      ppo=PPOConfig(num_mini_batches=2, num_learning_epochs=1),
                      distill=WarmStartConfig(rounds=1, steps_per_round=8, epochs=2),
                      out=str(tmp_path), run_name="ws", export_onnx=False)  # fmt: skip
    result = train(cfg, verbose=False)
    report = json.loads((result.run_dir / "warmstart.json").read_text())
    assert report["coach"] == "built-in coach 'posture'" and report["samples"] == 32
    with pytest.raises(ValueError, match="neither a built-in coach"):
        train(dataclasses.replace(cfg, warmstart=str(tmp_path), run_name="bad"), verbose=False)
    with pytest.raises(ValueError, match="needs an assist head"):
        dataclasses.replace(cfg, mode="baseline")


@pytest.mark.slow
def test_warmstart_from_a_dance_artifact_distils_its_coach(tmp_path):
    """The oracle's coach of the built-in dance, followed at each env's clip time (~1 min)."""
    from optimal_control.artifact import OracleArtifact
    from optimal_control.oracle import OracleConfig, solve_dance, solve_walk
    from optimal_control.walk import WalkConfig

    quick = OracleConfig(alphas=(1.0, 0.5), video=False, progress=False)
    _, dance_dir = solve_dance(None, dataclasses.replace(quick, out=str(tmp_path / "dance")))
    cfg = TrainConfig(task="dance", mode="a2cf", warmstart=str(dance_dir), iterations=1,
                      num_steps_per_env=8, env=EnvConfig(num_envs=8, num_threads=2),
                      model=TINY_MODEL, ppo=PPOConfig(num_mini_batches=2, num_learning_epochs=1),
                      distill=WarmStartConfig(rounds=2, steps_per_round=24, epochs=10),
                      out=str(tmp_path), run_name="dance", export_onnx=False)  # fmt: skip
    run = train(cfg, verbose=False).run_dir
    report = json.loads((run / "warmstart.json").read_text())
    assert "coach and eta0 of the oracle artifact" in report["coach"]
    eta0 = json.loads((run / "config.json").read_text())["eta0"]
    oracle = OracleArtifact.read_summary(dance_dir).eta0
    torch.testing.assert_close(torch.tensor(eta0), torch.tensor(oracle, dtype=torch.float32))
    assert report["held_out_fit"]["my"]["coach_mean_abs"] > 0
    _, walk_dir = solve_walk(
        WalkConfig(duration=2.5), dataclasses.replace(quick, out=str(tmp_path / "walk"))
    )
    # walk draws random commands: the artifact sets eta0, the built-in posture coach is distilled
    walk = train(dataclasses.replace(cfg, task="walk", warmstart=str(walk_dir), run_name="walk"),
                 verbose=False).run_dir  # fmt: skip
    report = json.loads((walk / "warmstart.json").read_text())
    assert "coach: built-in 'posture'" in report["coach"]
    eta0 = json.loads((walk / "config.json").read_text())["eta0"]
    oracle = OracleArtifact.read_summary(walk_dir).eta0
    torch.testing.assert_close(torch.tensor(eta0), torch.tensor(oracle).max(0).values[None].float())


def test_motion_warm_start_clones_the_dance_reference_and_refuses_tasks_without_one(tmp_path):
    """--warmstart-motion: the motion head's joint targets match the reference's next frame on
    held-out states (the untrained head is nowhere near), also in mode baseline; a task without a
    time-indexed joint reference is refused with a message naming the flag."""
    from rl.a2cf.warmstart import distill_motion_head
    from rl.training.runner import build_training

    standing = {"actions_around_reference": False}  # the clone's target is a standing offset
    cfg = TrainConfig(task="dance", mode="baseline", env=EnvConfig(num_envs=16, num_threads=2),
                      model=TINY_MODEL, ppo=PPOConfig(num_mini_batches=2),
                      task_overrides=standing)  # fmt: skip
    env, runner, _ = build_training(cfg, run_dir=None)
    learner = runner.env
    target = env.joint_targets_to_actions(env.command_gen.reference_joint_pos_rad())
    before = (runner.alg.actor(env.get_observations()) - target).square().mean()
    report = distill_motion_head(runner.alg.actor, learner,
                                 WarmStartConfig(rounds=3, steps_per_round=24, epochs=80))  # fmt: skip
    assert report["r2"] > 0.5, report
    obs = env.get_observations()
    target = env.joint_targets_to_actions(env.command_gen.reference_joint_pos_rad())
    after = (runner.alg.actor(obs) - target).square().mean()
    assert after < 0.5 * before
    assert set(report["held_out_fit"]) == {"legs", "waist", "arms"}
    env.close()
    stand = TrainConfig(mode="baseline", warmstart_motion=True, iterations=1, num_steps_per_env=8,
                        env=EnvConfig(num_envs=4, num_threads=2), model=TINY_MODEL,
                        ppo=PPOConfig(num_mini_batches=2, num_learning_epochs=1),
                        out=str(tmp_path), run_name="stand", export_onnx=False)  # fmt: skip
    with pytest.raises(ValueError, match="--warmstart-motion needs a time-indexed joint reference"):
        train(stand, verbose=False)
    assert not (tmp_path / "stand").exists()  # refused before the run folder is made
    around = dataclasses.replace(stand, task="dance", run_name="dance")
    with pytest.raises(ValueError, match="around the reference already"):
        train(around, verbose=False)


def test_artifact_coach_follows_the_backflip_from_its_start_command(tmp_path, g1_pin):
    """The backflip's reference time counts from the start command, which the artifact's
    reference reaches at the first frame of its Crouch; before the start the coach holds the
    first frame. An artifact without that phase is refused by name."""
    import numpy as np

    from optimal_control.artifact import build_artifact
    from optimal_control.reference import static_reference
    from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig
    from rl.a2cf.coaches import ArtifactCoach
    from rl.tasks.backflip import terms as bt
    from rl.tasks.backflip.task import BACKFLIP

    ref = static_reference(g1_pin.q_stand, 10, 0.02, name="flip")
    ref.phase = np.array([0, 0, 0, 1, 1, 2, 2, 3, 3, 4])
    ref.phase_names = bt.BACKFLIP_PHASES
    ref.q[:, 0] = np.linspace(0.0, -0.45, 10)  # the pelvis moves back along the reference
    ref.validate()
    profile = {a: WrenchQP(WrenchQPConfig(alpha=a)).solve_reference(ref) for a in (1.0, 0.5)}
    folder = build_artifact("backflip", ref, profile).save(tmp_path / "flip")
    coach = ArtifactCoach(str(folder))
    assert coach.anchor_time_s("crouch") == pytest.approx(0.06)
    env = make_env(quiet(BACKFLIP), 4, num_threads=1)
    try:
        env.env_state  # noqa: B018 - the state exists before any step
        command = env.command_gen
        assert command.reference_anchor_phase == "crouch"
        assert (command.reference_time_s() < 0).all()  # waiting for the start
        held = coach(env)  # on the first frame: the standing robot is within the band
        assert torch.isfinite(held).all() and held.abs().max() < 1e-6
        command.time_s[:] = command.delay_s + 0.12  # 0.18 s along the reference: x = -0.18
        ahead = coach(env)
        assert (ahead[:, 0] < 0).all()  # pulled back along the reference (heading frame: -x)
        assert (ahead.abs() <= env.env_state.assist_bound + 1e-6).all()
    finally:
        env.close()
    with pytest.raises(ValueError, match="does not have"):
        coach.anchor_time_s("jump_start")
