"""sim2sim drives every task's command and phases as training does, and the deployment bundle says
what the command's columns hold (``rl.evaluation.sim2sim.TaskLogic``, ``rl.agents.export.command_parts``)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from a2cf_mb.cli import main as cli_main
from rl.a2cf.config import CurriculumConfig
from rl.agents.export import export_motion_policy
from rl.agents.models import A2CFActor
from rl.envs.config import EnvConfig
from rl.envs.task_schema import TaskConfig, quiet
from rl.envs.terms import TerminationTerm
from rl.evaluation.config import AloneEvalConfig
from rl.evaluation.sim2sim import Sim2SimConfig, run_sim2sim
from rl.tasks import terminations
from rl.tasks.dance.task import DANCE_JOINTS as DANCE
from rl.tasks.registry import TASKS, make_env
from rl.tasks.stand.task import STAND
from rl.tasks.walk.task import WALK_FLAT
from rl.training.config import ModelConfig, PPOConfig, TrainConfig
from rl.training.runner import train

SIZES = dict(
    latent_dim=2, encoder_hidden_dims=(8,), motion_hidden_dims=(16,), assist_hidden_dims=(8,)
)


def export_neutral_policy(env, folder: Path) -> dict:
    """``policy.onnx`` + ``policy.json`` of an untrained actor on ``env`` whose motion head outputs
    zeros (joint targets = the stand pose), so robots stay up for a while; returns the bundle."""
    actor = A2CFActor(
        env.get_observations(), {"actor": ["policy", "history", "privileged"]}, "actor", 35,
        **SIZES, distribution_cfg={"class_name": "GaussianDistribution", "init_std": 1.0},
    )  # fmt: skip
    with torch.no_grad():
        actor.mlp.motion[-1].weight.zero_()
        actor.mlp.motion[-1].bias.zero_()
    export_motion_policy(actor, folder / "policy.onnx", env=env)
    return json.loads((folder / "policy.json").read_text())


def command_term(bundle: dict) -> dict | None:
    """The bundle's command term (None: the policy reads no command)."""
    return next((t for t in bundle["observation"]["terms"] if t["name"] == "command"), None)


def replay_commands(task: TaskConfig, num_envs: int, seed: int, state, num_steps: int) -> list:
    """The commands (N, C) per step that the task's command generator, built from ``seed`` in its
    evaluation setting, gives when driven as the training env drives it (``rl.envs.vec_env``):
    every part's ``reset_state`` then ``reset``, then ``compute(state, 0)`` at the reset and
    ``compute(state, dt)`` after each step."""
    generator = torch.Generator().manual_seed(seed)
    command = task.commands.build(num_envs, generator)
    phases = task.phases.build(num_envs, generator)
    ids = torch.arange(num_envs)
    qpos = torch.zeros(num_envs, 36, dtype=torch.float64)
    qvel = torch.zeros(num_envs, 35, dtype=torch.float64)
    for part in (command, phases):
        part.for_evaluation()
        part.reset_state(ids, qpos, qvel, generator)
    command.reset(ids)
    phases.reset(ids)
    if getattr(task.evaluation, "judge_kinds", False):  # the walk's judge holds a kind per env
        from rl.tasks.walk.evaluation import JUDGED_KINDS, judged_commands

        kinds, held = judged_commands(task.commands, num_envs)
        command.hold(kinds != JUDGED_KINDS.index("mixed"), held)
    out = [command.compute(state, 0.0).clone()]
    for _ in range(num_steps - 1):
        out.append(command.compute(state, state.step_dt_s).clone())
    return out


@pytest.mark.parametrize("name", sorted(TASKS))
def test_sim2sim_feeds_every_task_the_command_its_generator_makes(tmp_path, name: str) -> None:
    task = TASKS[name]
    n, seed = 2, 3
    env = make_env(task, n, num_threads=1)
    bundle = export_neutral_policy(env, tmp_path)
    term = command_term(bundle)
    if task.commands.dim == 0:
        assert term is None
    else:  # the bundle's parts tile the command's columns, each with a unit and a description
        start, stop = term["columns"]
        assert stop - start == task.commands.dim
        edges = [start] + [p["columns"][1] for p in term["parts"]]
        assert [p["columns"][0] for p in term["parts"]] == edges[:-1] and edges[-1] == stop
        assert all(p["unit"] and p["compute"] for p in term["parts"])
    seen: list[np.ndarray] = []
    result = run_sim2sim(
        tmp_path, task, 60, Sim2SimConfig(num_envs=n, seed=seed), on_step=seen.append
    )
    assert 0.0 <= result["survival_fraction"] <= 1.0 and math.isfinite(result["mean_return"])
    assert result["mean_episode_length_steps"] >= 10  # a neutral policy stands a while
    if term is None:
        return
    expected = replay_commands(task, n, seed, env.env_state, len(seen))
    start, stop = term["columns"]
    # columns that read the robot's own state (a tracking task's anchor seen from the robot) differ
    # between the two simulators' robots; every other column is the generator's alone
    own = np.concatenate([np.arange(*p["columns"]) - start for p in term["parts"]
                          if not p.get("from_robot", False)])  # fmt: skip
    for step, (obs, command) in enumerate(zip(seen, expected, strict=True)):
        assert np.isfinite(obs[:, start:stop]).all()
        np.testing.assert_allclose(
            obs[:, start:stop][:, own], command.numpy()[:, own], atol=1e-6, err_msg=step
        )


def test_backflip_bundle_and_sim2sim_start_signal(tmp_path) -> None:
    """The start signal is 0 while the robot waits, 1 once the delay its seed draws has passed."""
    task = TASKS["backflip"]
    env = make_env(task, 2, num_threads=1)
    bundle = export_neutral_policy(env, tmp_path)
    term = command_term(bundle)
    assert [p["name"] for p in term["parts"]] == ["start"]
    seen: list[np.ndarray] = []
    run_sim2sim(tmp_path, task, 60, Sim2SimConfig(num_envs=2, seed=5), on_step=seen.append)
    assert len(seen) == 60
    signal = np.stack([obs[:, term["columns"][0]] for obs in seen])  # (T, N)
    generator = torch.Generator().manual_seed(5)
    start = task.commands.build(2, generator)
    start.reset(torch.arange(2))
    time_s = np.arange(60)[:, None] * env.step_dt_s
    np.testing.assert_array_equal(signal, time_s >= start.delay_s.numpy() - 1e-6)
    assert signal[0].tolist() == [0.0, 0.0] and signal[-1].tolist() == [1.0, 1.0]


def test_eval_sim2sim_of_a_walk_flat_run_follows_the_velocity_command(tmp_path, capsys) -> None:
    cfg = TrainConfig(
        task="walk-flat", iterations=1, num_steps_per_env=4, out=str(tmp_path), run_name="walk",
        env=EnvConfig(num_envs=4, num_threads=1), eval=AloneEvalConfig(interval=0),
        curriculum=CurriculumConfig(skill_measure="alone"),
        ppo=PPOConfig(num_mini_batches=2, num_learning_epochs=1),
        model=ModelConfig(motion_hidden_dims=(16,), assist_hidden_dims=(8,),
                          critic_hidden_dims=(16,), encoder_hidden_dims=(16,), latent_dim=2),
    )  # fmt: skip
    run = train(cfg, verbose=False).run_dir
    argv = ["eval", str(run), "--sim2sim", "--num-envs", "2", "--num-steps", "5"]
    assert cli_main(argv) == 0
    other = json.loads((run / "eval.json").read_text())["sim2sim"]
    assert 0.0 <= other["survival_fraction"] <= 1.0 and math.isfinite(other["mean_return"])
    assert other["mean_episode_length_steps"] > 0
    # the walk's judge scores the sim2sim robots too: velocity errors beside standing still's,
    # per command, in the table beside the training physics' figures
    judged = other["task_metrics"]
    assert judged["survival"] == other["survival_fraction"] and judged["per_command"]
    for key in ("lin_vel_error_mps", "yaw_rate_error_rps", "standing_still_lin_vel_error_mps"):
        assert math.isfinite(judged[key]) and judged[key] >= 0.0, key
    ours = json.loads((run / "eval.json").read_text())["task_metrics"]["per_command"]
    both = {r["command"] for r in ours} & {r["command"] for r in judged["per_command"]}
    table = capsys.readouterr().out.split("training physics")[1]
    assert "\nlin_vel_error_mps " in table and both
    assert all(f"\n{name}: lin_vel_error_mps " in table for name in both)
    term = command_term(json.loads((run / "policy.json").read_text()))
    start, stop = term["columns"]
    assert stop - start == 5  # vx, vy, yaw rate, gait clock (sin, cos)
    assert [p["name"] for p in term["parts"]] == [
        "lin_vel_x",
        "lin_vel_y",
        "ang_vel_z",
        "gait_clock",
    ]

    # Commands redrawn every 0.1-0.3 s: sim2sim shows the policy what the generator draws, when
    # the training env would (same seed, same schedule); the judge's held kinds off, so that
    # every env draws.
    from rl.tasks.walk.evaluation import WalkEvaluationConfig

    task = dataclasses.replace(
        WALK_FLAT,
        evaluation=WalkEvaluationConfig(),
        commands=dataclasses.replace(
            WALK_FLAT.commands, resampling_time_range_s=(0.1, 0.3), curriculum_initial_scale=0.3
        ),
    )
    n, seed = 3, 7
    seen: list[np.ndarray] = []
    run_sim2sim(run, task, 25, Sim2SimConfig(num_envs=n, seed=seed), on_step=seen.append)
    env = make_env(quiet(task), n, num_threads=1)
    expected = replay_commands(task, n, seed, env.env_state, len(seen))
    commands = np.stack([obs[:, start:stop] for obs in seen])  # (T, N, 5)
    np.testing.assert_allclose(commands, torch.stack(expected).numpy(), atol=1e-6)
    assert len(np.unique(commands[:, 0, :3], axis=0)) > 2  # the commands were redrawn
    vx, (low, high) = commands[..., 0], task.commands.lin_vel_x_range_mps
    scale = task.commands.curriculum_initial_scale  # training's ranges start at 30 %
    assert ((low <= vx) & (vx <= high)).all() and (vx > scale * high).any()  # full ranges
    # The gait clock at step k is the training env's at step k (time since the episode's start).
    for step in range(len(seen)):
        clock = env.observation_term("policy_clean", "command")[:, 3:5].numpy()
        np.testing.assert_allclose(commands[step, :, 3:5], clock, atol=1e-5, err_msg=step)
        _, _, dones, _ = env.step(torch.zeros(n, 35))
        assert not dones.any()


def test_sim2sim_dance_starts_on_its_clip_frame_and_follows_the_clip(tmp_path) -> None:
    n, seed = 2, 4
    env = make_env(DANCE, n, num_threads=1)
    bundle = export_neutral_policy(env, tmp_path)
    term = command_term(bundle)
    assert [p["name"] for p in term["parts"]] == [
        "base_step_displacement", "base_step_rotation", "joint_pos_ref"]  # fmt: skip
    seen: list[np.ndarray] = []
    exact = Sim2SimConfig(num_envs=n, seed=seed, randomize=False)  # no observation noise
    run_sim2sim(tmp_path, DANCE, 20, exact, on_step=seen.append)
    assert len(seen) >= 5
    # The clip frames this seed draws (the command's own draws, as in training).
    generator = torch.Generator().manual_seed(seed)
    reference = DANCE.commands.build(n, generator)
    reference.reset_state(torch.arange(n), torch.zeros(n, 36).double(), torch.zeros(n, 35).double(), generator)  # fmt: skip
    lib, first = reference.library, reference.start_frame.numpy()
    columns = {t["name"]: t["columns"] for t in bundle["observation"]["terms"]}
    default = np.array([j["default_pos_rad"] for j in bundle["joints"]])
    joint_pos = seen[0][:, slice(*columns["joint_pos"])] + default
    np.testing.assert_allclose(joint_pos, lib.qpos[first, 7:], atol=1e-6)  # on the frame
    start, stop = term["columns"]
    for k, obs in enumerate(seen):  # step k shows frame start + k + 1, as the env's does
        np.testing.assert_allclose(obs[:, start:stop], lib.command[first + k + 1], atol=1e-6)
    env_first = env.command_gen.start_frame.numpy()
    for k in range(5):
        command = env.observation_term("policy_clean", "command").numpy()
        np.testing.assert_allclose(command, lib.command[env_first + k + 1], atol=1e-6)
        _, _, dones, _ = env.step(torch.zeros(n, 35))
        assert not dones.any()


def test_sim2sim_robots_on_one_reference_frame_differ_by_their_own_draws(tmp_path) -> None:
    """Every tracking robot starts on the reference's first frame; each has its own draw of the
    task's friction, payload and CoM (its own model) and its own observation noise, so the N
    rollouts differ (``randomize``); without them (or on a ``quiet`` task) they are one rollout."""
    from rl.evaluation.sim2sim import observation_noise
    from rl.tasks.registry import get_task

    task, n = get_task("track"), 3
    env = make_env(task, n, num_threads=1)
    bundle = export_neutral_policy(env, tmp_path)
    env.close()
    noise = observation_noise(bundle, task)
    columns = {t["name"]: t["columns"] for t in bundle["observation"]["terms"]}
    amplitude = {t.name: t.noise for t in task.observations.policy.terms}
    for name, (start, stop) in columns.items():
        assert (noise[start:stop] == amplitude[name]).all()
    assert noise.any() and not observation_noise(bundle, quiet(task)).any()

    def rollout(cfg: Sim2SimConfig, on: TaskConfig = task) -> tuple[dict, np.ndarray]:
        seen: list[np.ndarray] = []
        result = run_sim2sim(tmp_path, on, 30, cfg, on_step=seen.append)
        return result, np.stack(seen)  # (T, N, P)

    same, obs = rollout(Sim2SimConfig(num_envs=n, seed=2, randomize=False))
    assert not same["randomized"] and not same["observation_noise"]
    np.testing.assert_array_equal(obs[:, 1:], np.broadcast_to(obs[:, :1], obs[:, 1:].shape))
    drawn, noisy = rollout(Sim2SimConfig(num_envs=n, seed=2))
    assert drawn["randomized"] and drawn["observation_noise"]
    first = noisy[0] - obs[0]  # the same start: only the noise differs, within its half-width
    assert (np.abs(first) <= noise + 1e-6).all() and (first[:, noise > 0] != 0).mean() > 0.99
    np.testing.assert_allclose(first[:, noise == 0], 0.0, atol=1e-6)  # the command: noiseless
    later = np.abs(noisy[-1] - noisy[-1, :1]).max(axis=-1)  # the robots' own physics parted them
    assert (later[1:] > 0).all()
    assert rollout(Sim2SimConfig(num_envs=n, seed=2), quiet(task))[0]["randomized"] is False


def test_sim2sim_link_contacts_end_an_episode(tmp_path) -> None:
    """The sim2sim robots' link-ground contacts (URDF meshes on the floor) feed the task's
    ``link_on_ground`` termination: a robot laid on its back fails at its first step, a standing
    one does not."""
    export_neutral_policy(make_env(STAND, 1, num_threads=1), tmp_path)
    on_ground = TerminationTerm(
        "base_contact", terminations.link_on_ground, params={"bodies": ("pelvis", "torso_link")}
    )
    task = dataclasses.replace(STAND, terminations=(on_ground,))
    standing = run_sim2sim(tmp_path, task, 5, Sim2SimConfig(num_envs=2))
    assert standing["survival_fraction"] == 1.0 and standing["mean_episode_length_steps"] == 5

    def on_its_back(env_ids, qpos, qvel, generator) -> None:
        qpos[:, 2] = 0.05  # pelvis height [m]: its back mesh a little into the floor
        qpos[:, 3:7] = torch.tensor([math.cos(math.pi / 4), 0.0, -math.sin(math.pi / 4), 0.0])

    lying = dataclasses.replace(
        task, initial_state=dataclasses.replace(task.initial_state, reset_state=on_its_back)
    )
    fallen = run_sim2sim(tmp_path, lying, 5, Sim2SimConfig(num_envs=2))
    assert fallen["survival_fraction"] == 0.0 and fallen["mean_episode_length_steps"] == 1


def test_sim2sim_pushes_the_robots_as_training_does() -> None:
    from rl.envs.task_schema import PushConfig
    from rl.evaluation.sim2sim import _Pushes

    cfg = PushConfig(interval_range_s=(3.0, 6.0), velocity_xy_mps=0.5)
    pushes = _Pushes(cfg, 16, seed=0)
    kicks = np.stack([pushes.kicks(0.02) for _ in range(500)])  # 10 s
    per_robot = (np.abs(kicks).sum(-1) > 0).sum(0)
    assert per_robot.min() >= 1 and per_robot.max() <= 3  # one kick every 3-6 s
    assert np.abs(kicks).max() <= 0.5
    off = _Pushes(PushConfig(enabled=False), 4, seed=0)
    assert not np.any([off.kicks(0.02) for _ in range(500)])


def test_sim2sim_settings_can_be_set_back_to_the_training_physics() -> None:
    """Each second-simulator setting can take the training physics' value (to find where a gap
    comes from); a wrong name is refused with the options."""
    from rl.envs.model import build_physics_model, contact_bodies
    from rl.evaluation.sim2sim import build_sim2sim_model

    own = build_sim2sim_model(Sim2SimConfig())
    assert own.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert own.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert (own.geom_type == mujoco.mjtGeom.mjGEOM_MESH).any()
    back = build_sim2sim_model(
        Sim2SimConfig(cone="pyramidal", integrator="implicitfast", link_meshes=False)
    )
    assert back.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    assert back.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    colliding = (back.geom_contype != 0) & (back.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    assert not colliding.any()  # the link primitives collide instead, on the same links
    assert contact_bodies(back) == contact_bodies(build_physics_model())
    with pytest.raises(ValueError, match="cone 'cylinder' is not one of"):
        Sim2SimConfig(cone="cylinder")
    shins = build_sim2sim_model(Sim2SimConfig(links_off_floor=("left_knee_link",)))
    knee = shins.geom_bodyid == shins.body("left_knee_link").id
    assert (own.geom_contype[knee] == 2).any() and not shins.geom_contype[knee].any()
    with pytest.raises(ValueError, match="'left_shin' is not a link of the G1"):
        build_sim2sim_model(Sim2SimConfig(links_off_floor=("left_shin",)))
