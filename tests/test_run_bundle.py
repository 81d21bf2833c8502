"""A bundle deploys alone: the standalone runner (``a2cf_mb/deploy/run_bundle.py``, MuJoCo +
onnxruntime + numpy) rebuilds the training env's G1 from the bundle's facts and plays the same
episodes as the training env, and ``a2cf-mb eval`` takes a bundle folder."""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from a2cf_mb.cli import main as cli_main
from a2cf_mb.deploy import run_bundle as runner
from rl.agents.export import export_motion_policy
from rl.agents.models import A2CFActor
from rl.envs.task_schema import quiet
from rl.evaluation.alone import rollout_alone
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND
from rl.tasks.track.task import track_task

SIZES = dict(
    latent_dim=2, encoder_hidden_dims=(8,), motion_hidden_dims=(16,), assist_hidden_dims=(8,)
)
STEPS = 60
"""Policy steps per episode (1.2 s): a fall or a clip's end within it, the default suite's size."""
VISUAL_FIELDS = ("geom_group", "geom_matid", "geom_rgba")
"""Model arrays that only draw: the runner's floor has no material, its geoms no colours."""


def export_policy(env, folder: Path, bias: np.ndarray, weight_std: float) -> dict:
    """Export an untrained actor on ``env`` whose motion head is ``bias`` (29,) plus random
    weights of std ``weight_std`` (the actions follow the observation); returns the bundle."""
    torch.manual_seed(0)
    actor = A2CFActor(
        env.get_observations(), {"actor": ["policy", "history", "privileged"]}, "actor", 35,
        **SIZES, distribution_cfg={"class_name": "GaussianDistribution", "init_std": 1.0},
    )  # fmt: skip
    with torch.no_grad():
        actor.mlp.motion[-1].weight.normal_(0.0, weight_std)
        actor.mlp.motion[-1].bias.copy_(torch.as_tensor(bias))
    folder.mkdir(parents=True, exist_ok=True)
    export_motion_policy(actor, folder / "policy.onnx", env=env)
    return json.loads((folder / "policy.json").read_text())


def training_rollout(env, folder: Path) -> dict:
    """The training env's evaluation (``rollout_alone``) of the bundle's ONNX policy."""
    from rl.agents.export import OnnxMotionPolicy

    onnx = OnnxMotionPolicy(folder / "policy.onnx")

    def policy(obs):
        return torch.from_numpy(onnx(obs["policy"].numpy(), obs["history"].numpy()))

    return rollout_alone(env, policy, STEPS)


def test_the_runner_imports_nothing_of_the_project() -> None:
    tree = ast.parse(Path(runner.__file__).read_text())
    imported = {
        (node.module if isinstance(node, ast.ImportFrom) else alias.name).split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in node.names
    }
    allowed = {"mujoco", "onnxruntime", "numpy", "__future__"}
    import sys

    assert imported - allowed <= set(sys.stdlib_module_names), imported - allowed


def test_a_falling_stand_policy_falls_alike_in_the_runner_and_the_training_env(tmp_path) -> None:
    env = make_env(quiet(STAND), 2, num_threads=1)
    bias = np.zeros(29)
    bias[[0, 6]], bias[[3, 9]] = -3.0, 3.0  # hips and knees bend: the robot sits down
    bundle = export_policy(env, tmp_path / "stand", bias, weight_std=0.05)
    # The facts rebuild the training model exactly (the URDF, then the bundle's geoms, joints,
    # actuators and options): the same floats, so the two simulators differ by float32 rounding.
    model = runner.build_model(runner.load_bundle(tmp_path / "stand"))
    trained = env.physics.model
    fields = [name for name in dir(trained) if name.startswith(("opt", "geom_", "body_", "dof_",
              "jnt_", "actuator_")) and isinstance(getattr(trained, name), np.ndarray)]  # fmt: skip
    assert len(fields) > 50
    for field in sorted(set(fields) - set(VISUAL_FIELDS)):
        np.testing.assert_array_equal(getattr(model, field), getattr(trained, field), field)
    for field in ("timestep", "integrator", "cone", "impratio", "solver", "iterations"):
        assert getattr(model.opt, field) == getattr(trained.opt, field), field
    assert bundle["model"]["options"]["integrator"] == "mjINT_IMPLICITFAST"
    assert [j["armature_kgm2"] for j in bundle["model"]["joints"]][3] == pytest.approx(0.0251)
    ours = training_rollout(env, tmp_path / "stand")
    env.close()
    theirs = runner.run_bundle(tmp_path / "stand", num_envs=2, num_steps=STEPS, noise=False)
    assert ours["survival_fraction"] == theirs["survival_fraction"] == 0.0
    # float32 (training's observations and targets) against float64 rounding: the fall comes at
    # the same step, at most one apart
    assert abs(ours["mean_episode_length_steps"] - theirs["mean_episode_length_steps"]) <= 1.0
    assert theirs["mean_episode_length_steps"] < STEPS


@pytest.fixture(scope="module")
def clips(tmp_path_factory, g1_pin) -> tuple[str, str]:
    """Two 1.2 s, 50 fps NPZ clips of the stand pose: arms waving; legs folding under a pelvis
    that stays up (the feet lift: the robot falls)."""
    frames = 60
    t = np.arange(frames) / 50.0
    wave = np.tile(g1_pin.q_stand, (frames, 1))
    wave[:, 7 + 15] += 0.6 * np.sin(2 * np.pi * 0.8 * t)  # left shoulder pitch
    wave[:, 7 + 22] -= 0.6 * np.sin(2 * np.pi * 0.8 * t)  # right shoulder pitch
    fold = np.tile(g1_pin.q_stand, (frames, 1))
    bend = 0.25 * (1 - np.cos(2 * np.pi * 0.8 * t))
    for hip, knee, ankle in ((0, 3, 4), (6, 9, 10)):
        fold[:, 7 + hip] -= bend
        fold[:, 7 + knee] += 2 * bend
        fold[:, 7 + ankle] -= bend
    folder = tmp_path_factory.mktemp("clips")
    np.savez(folder / "wave.npz", qpos=wave, fps=50.0)
    np.savez(folder / "fold.npz", qpos=fold, fps=50.0)
    return str(folder / "wave.npz"), str(folder / "fold.npz")


@pytest.mark.filterwarnings("ignore:.*no sole in contact")
def test_a_tracking_bundle_plays_its_reference_as_the_training_env_does(tmp_path, clips) -> None:
    task = track_task(clips)
    task = quiet(dataclasses.replace(
        task, action_feedforward=True,
        commands=dataclasses.replace(task.commands, hold_s=0.1),
    ))  # fmt: skip
    env = make_env(task, 4, num_threads=1)
    bundle = export_policy(env, tmp_path / "track", np.zeros(29), weight_std=0.05)
    section = bundle["reference"]
    ref = np.load(tmp_path / "track" / section["file"])
    # two clips of 60 frames, each with 5 held frames at both ends: rates zero where held
    assert list(ref["clip_length"]) == [70, 70] and section["hold_frames"] == 5
    assert not ref["joint_vel_rps"][:5].any() and not ref["joint_vel_rps"][65:70].any()
    assert section["bodies"][0] == "pelvis" and section["anchor_body"] == "torso_link"
    assert [c["source"] for c in section["clips"]] == list(clips)
    ours = training_rollout(env, tmp_path / "track")
    env.close()
    theirs = runner.run_bundle(tmp_path / "track", num_envs=4, num_steps=STEPS, noise=False)
    # the wave is tracked to its end (cut at STEPS); the fold lifts the feet: a fall, in both
    assert ours["survival_fraction"] == theirs["survival_fraction"] == 0.5
    assert ours["mean_episode_length_steps"] == theirs["mean_episode_length_steps"]
    assert ours["task_metrics"]["frames_scored"] == theirs["task_metrics"]["frames_scored"]
    # The same model, start and policy: only the rounding differs (training's observations and
    # targets in float32, the runner's in float64), about 1e-9 over these steps; 1e-6 leaves room
    # for other CPUs and is far below the errors themselves (centimetres, hundredths of a radian).
    for key in ("joint_error_rad", "pelvis_pos_error_m", "pelvis_rot_error_rad",
                "body_pos_error_m", "body_rel_error_m"):  # fmt: skip
        assert abs(ours["task_metrics"][key] - theirs["task_metrics"][key]) < 1e-6, key
    assert theirs["task_metrics"]["joint_error_rad"] > 10 * 1e-3


def test_a_walk_bundle_follows_its_velocity_command_as_the_training_env_does(tmp_path) -> None:
    from rl.tasks.walk.task import WALK_FLAT

    task = quiet(WALK_FLAT)
    task = dataclasses.replace(task, evaluation=task.evaluation.scripted())
    env = make_env(task, 2, num_threads=1)
    bundle = export_policy(env, tmp_path / "walk", np.zeros(29), weight_std=0.05)
    parts = [p["name"] for t in bundle["observation"]["terms"] for p in t.get("parts", [])]
    assert "gait_clock" in parts  # the runner reads its period from the part's text
    ours = training_rollout(env, tmp_path / "walk")
    env.close()
    first = task.evaluation.command_script[0]  # STEPS stay within the script's first segment
    assert first.duration_s * 50 > STEPS and any(first.command)
    script = ((first.duration_s, first.command),)
    theirs = runner.run_bundle(tmp_path / "walk", num_envs=2, num_steps=STEPS, noise=False,
                               script=script)  # fmt: skip
    assert ours["survival_fraction"] == theirs["survival_fraction"]
    assert ours["mean_episode_length_steps"] == theirs["mean_episode_length_steps"]
    for key in ("lin_vel_error_mps", "yaw_rate_error_rps"):  # same episodes: rounding only
        assert abs(ours["task_metrics"][key] - theirs["task_metrics"][key]) < 1e-6, key


def test_eval_takes_a_bundle_folder(tmp_path, capsys) -> None:
    env = make_env(quiet(STAND), 2, num_threads=1)
    export_policy(env, tmp_path / "stand", np.zeros(29), weight_std=0.0)
    env.close()
    code = cli_main(["eval", str(tmp_path / "stand"), "--num-envs", "2", "--num-steps", "10"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["task"] == "stand" and result["survival_fraction"] == 1.0
    assert result["num_steps"] == 10


def test_a_bundle_of_an_older_format_is_made_whole_without_its_checkpoint(tmp_path) -> None:
    from rl.agents.export import refresh_bundle
    from rl.tasks.walk.task import WALK_FLAT

    env = make_env(quiet(STAND), 2, num_threads=1)
    export_policy(env, tmp_path / "stand", np.zeros(29), weight_std=0.0)
    path = tmp_path / "stand" / "policy.json"
    bundle = json.loads(path.read_text())
    old = {k: v for k, v in bundle.items() if k not in ("model", "episode")}
    old["format"] = "a2cf-mb-policy/2"
    path.write_text(json.dumps(old))
    with pytest.raises(runner.BundleError, match="export the policy again"):
        runner.run_bundle(tmp_path / "stand", num_envs=1, num_steps=2)
    walk = make_env(quiet(WALK_FLAT), 1, num_threads=1)
    with pytest.raises(ValueError, match="not this policy"):  # another task's interface
        refresh_bundle(tmp_path / "stand", walk)
    walk.close()
    refresh_bundle(tmp_path / "stand", env)
    assert json.loads(path.read_text()) == bundle  # the facts as an export writes them
    env.close()
    assert runner.run_bundle(tmp_path / "stand", num_envs=1, num_steps=5)["survival_fraction"] == 1
