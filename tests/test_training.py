"""Training loop on the real batched MuJoCo G1 env: every mode, checkpoint/resume, CLI, learning."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from a2cf_mb.cli import main as cli_main
from optimal_control.bounds import PAPER_ETA0
from rl.a2cf.config import CurriculumConfig
from rl.envs.config import EnvConfig
from rl.evaluation.policy import EvalConfig, evaluate
from rl.runs.folder import CHECKPOINT_DIR, CURRICULUM_LOG, LAST_CHECKPOINT
from rl.training.config import ModelConfig, PPOConfig, TrainConfig
from rl.training.runner import train

WALK_ROW = PAPER_ETA0["walk"]["all"]

TINY_MODEL = ModelConfig(
    motion_hidden_dims=(32, 32),
    assist_hidden_dims=(16,),
    critic_hidden_dims=(32, 32),
    encoder_hidden_dims=(32,),
    latent_dim=4,
)
TINY_PPO = PPOConfig(num_learning_epochs=1, num_mini_batches=2)


def tiny_config(tmp_path, mode: str, **changes) -> TrainConfig:
    """4 envs x 8 steps per iteration, small networks."""
    base = TrainConfig(
        task="stand",
        mode=mode,
        env=EnvConfig(num_envs=4, num_threads=2),
        iterations=2,
        num_steps_per_env=8,
        out=str(tmp_path),
        run_name=mode,
        save_interval=1,
        ppo=TINY_PPO,
        model=TINY_MODEL,
    )
    return dataclasses.replace(base, **changes)


MEAN_RULE = CurriculumConfig(force_measure="mean")
"""The paper's force rule (the default has none), with the alone envs of the default."""


def read_jsonl(path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


@pytest.mark.parametrize("mode", ["baseline", "a2cf", "no-pi", "no-id", "no-rm"])
def test_two_iterations_of_every_mode(tmp_path, mode: str) -> None:
    result = train(tiny_config(tmp_path, mode), verbose=False)
    run = result.run_dir
    assert result.iterations_done == 2
    for name in ("config.json", "git.json", "metrics.json", "policy.onnx", "policy.json"):
        assert (run / name).is_file(), name
    assert list(run.glob("events.out.tfevents*")), "no TensorBoard events"
    assert (run / CHECKPOINT_DIR / LAST_CHECKPOINT).is_file()
    metrics = json.loads((run / "metrics.json").read_text())
    assert len(metrics["iterations"]) == 2
    assert metrics["onnx"]["max_abs_error"] < 1e-4
    assert all(torch.isfinite(torch.tensor(r["mean_step_reward"])) for r in metrics["iterations"])
    assert all(1e-5 <= r["learning_rate"] <= 1e-2 for r in metrics["iterations"])  # rsl-rl's range
    state = torch.load(run / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    actor_keys = state["actor_state_dict"].keys()
    has_assist_head = any(k.startswith("mlp.assist.") for k in actor_keys)
    assert has_assist_head == (mode != "baseline")
    if mode == "baseline":
        assert not (run / CURRICULUM_LOG).exists()
        assert all(r["applied_force_n"] == 0.0 for r in metrics["iterations"])
        return
    log = read_jsonl(run / CURRICULUM_LOG)
    assert [line["iteration"] for line in log] == [0, 1]
    assert all(line["visited"] == [True] for line in log)
    assert all(line["applied_force_n"] > 0.0 for line in log)  # the assist head pushed the robot
    eta0 = json.loads((run / "config.json").read_text())["eta0"]
    if mode == "no-id":
        assert eta0[0][0] == eta0[0][1] == eta0[0][2] and eta0[0][3] == eta0[0][4] == eta0[0][5]
    else:
        assert eta0 == WALK_ROW
    if mode == "a2cf":
        from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

        tags = set(EventAccumulator(str(run)).Reload().Tags()["scalars"])
        expected = {
            "Loss/surrogate", "Loss/value", "Loss/vae_reconstruction", "Reward/alive",
            "Curriculum/eta_stand_fx", "Curriculum/eta_stand_mz", "Curriculum/applied_force_n",
            "Curriculum/skill_progress", "Train/mean_step_reward",
        }  # fmt: skip
        assert expected <= tags, expected - tags
    uses_privileged = mode in ("a2cf", "no-id", "no-rm")
    config = json.loads((run / "config.json").read_text())
    assert ("privileged" in config["rsl_rl"]["obs_groups"]["actor"]) == uses_privileged


def test_resume_continues_iterations_and_curriculum(tmp_path) -> None:
    # Algorithm 1's factors alone (the schedule's cap follows num_updates, checked at the end)
    cfg = tiny_config(tmp_path, "a2cf", curriculum=CurriculumConfig(anneal_iterations=0))
    first = train(cfg, verbose=False)
    assert first.iterations_done == 2
    ckpt = torch.load(first.run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    assert ckpt["completed_iterations"] == 2
    eta_at_stop = ckpt["a2cf"]["curriculum"]["eta"]
    # "kill" = the process stopped after iteration 2, here just after logging a third iteration
    # whose checkpoint was never written: the resume drops that line and redoes the iteration
    with open(first.run_dir / CURRICULUM_LOG, "a") as f:
        f.write(json.dumps({"iteration": 2, "eta": [[0.0] * 6]}) + "\n")
    with open(first.run_dir / "metrics.jsonl", "a") as f:
        f.write(json.dumps({"iteration": 2, "completed": 3}) + "\n")
    resumed = train(
        dataclasses.replace(TrainConfig(), resume=str(first.run_dir), iterations=4), verbose=False
    )
    assert resumed.iterations_done == 4
    log = read_jsonl(first.run_dir / CURRICULUM_LOG)
    assert [line["iteration"] for line in log] == [0, 1, 2, 3]
    torch.testing.assert_close(torch.tensor(log[1]["eta"]), eta_at_stop)
    # the third update started from the stored bound: it is eta_at_stop scaled by 0.8, 1 or 1.2
    ratio = torch.tensor(log[2]["eta"]) / eta_at_stop
    assert torch.allclose(ratio, ratio[0, 0].expand_as(ratio))
    # Algorithm 1 factors: 0.8 / 1 / 1.2, times 0.8 when the skill counts as learned
    assert any(abs(float(ratio[0, 0]) - r) < 1e-5 for r in (0.8, 1.0, 1.2, 0.64, 0.96))
    metrics = json.loads((first.run_dir / "metrics.json").read_text())
    assert [row["iteration"] for row in metrics["iterations"]] == [0, 1, 2, 3]
    live = read_jsonl(first.run_dir / "metrics.jsonl")  # what progress displays read
    assert [row["completed"] for row in live] == [1, 2, 3, 4]
    steps = cfg.env.num_envs * cfg.num_steps_per_env
    assert [row["total_env_steps"] for row in live] == [k * steps for k in (1, 2, 3, 4)]
    final = torch.load(first.run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    assert final["completed_iterations"] == 4
    assert final["a2cf"]["curriculum"]["num_updates"] == 4
    assert final["logger"]["tot_timesteps"] == 4 * cfg.env.num_envs * cfg.num_steps_per_env


def test_cli_train_then_eval(tmp_path) -> None:
    argv = [
        "train", "--task", "stand", "--mode", "a2cf", "--env-num-envs", "4", "--iterations", "1",
        "--num-steps-per-env", "8", "--out", str(tmp_path), "--run-name", "cli",
        "--ppo-num-mini-batches", "2", "--ppo-num-learning-epochs", "1",
        "--model-motion-hidden-dims", "32", "32", "--model-critic-hidden-dims", "32",
        "--model-encoder-hidden-dims", "32", "--model-assist-hidden-dims", "16",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    run = tmp_path / "cli"
    saved = json.loads((run / "config.json").read_text())["train"]
    assert saved["model"]["motion_hidden_dims"] == [32, 32] and saved["iterations"] == 1
    assert cli_main(["train", "--resume", str(run), "--iterations", "2"]) == 0
    assert len(read_jsonl(run / CURRICULUM_LOG)) == 2
    video = tmp_path / "eval.mp4"
    result = evaluate(run, EvalConfig(num_envs=4, num_steps=20, video=str(video), video_min_s=1.0))
    assert result["num_steps"] == 20 and 0.0 <= result["survival_fraction"] <= 1.0
    assert video.is_file() and video.stat().st_size > 0
    assert (run / "eval.json").is_file()
    assert cli_main(["eval", str(run), "--num-envs", "2", "--num-steps", "5", "--no-use-onnx"]) == 0


@pytest.mark.slow
def test_stand_return_rises_in_a_short_cpu_run(tmp_path) -> None:
    """64 envs x 24 steps x 80 iterations of a2cf on "stand" (about 2-3 min on 2 cores)."""
    cfg = TrainConfig(
        task="stand", mode="a2cf", env=EnvConfig(num_envs=64), iterations=80, num_steps_per_env=24,
        out=str(tmp_path), run_name="slow", save_interval=80,
    )  # fmt: skip
    rows = train(cfg, verbose=False).metrics["iterations"]
    returns = [r["mean_episode_return"] for r in rows if r["mean_episode_return"] is not None]
    lengths = [r["mean_episode_length"] for r in rows if r["mean_episode_length"] is not None]
    # rsl-rl's buffers hold the last 100 finished episodes: compare the first full buffers with the end
    first_return, last_return = sum(returns[2:7]) / 5, sum(returns[-5:]) / 5
    first_length, last_length = sum(lengths[2:7]) / 5, sum(lengths[-5:]) / 5
    print(
        f"episode return {first_return:.3f} -> {last_return:.3f}, length {first_length:.1f} -> {last_length:.1f}"
    )
    assert last_return > first_return
    assert last_length > first_length


def test_curriculum_shrinks_an_unused_bound_in_real_training(tmp_path) -> None:
    # A near-silent assist head (std 0.02 before tanh) applies far less than half the bound:
    # Algorithm 1 must shrink eta by (1 - delta) after every iteration.
    ppo = dataclasses.replace(TINY_PPO, assist_init_noise_std=0.02)
    result = train(tiny_config(tmp_path, "a2cf", ppo=ppo, curriculum=MEAN_RULE), verbose=False)
    log = read_jsonl(result.run_dir / CURRICULUM_LOG)
    eta0 = torch.tensor(WALK_ROW)
    for k, line in enumerate(log, start=1):
        assert line["applied_norm"][0] < 0.5 * float(
            torch.linalg.vector_norm(eta0 * 0.8 ** (k - 1))
        )
        torch.testing.assert_close(torch.tensor(line["eta"]), eta0 * 0.8**k)
    assert log[-1]["assist_enabled"]


PLAIN_KEYS = ("mean_step_reward", "mean_episode_return", "mean_episode_length", "skill_progress",
              "applied_force_n", "eta_norm", "assist_enabled", "losses", "learning_rate")  # fmt: skip


def test_killed_and_resumed_run_equals_the_uninterrupted_one(tmp_path) -> None:
    """Resume continues bit for bit on CPU (env rows, RNG streams, episode counters, history
    buffers, curriculum statistics, logger), here with the bound shrinking every iteration."""
    ppo = dataclasses.replace(TINY_PPO, assist_init_noise_std=0.02)
    whole = train(tiny_config(tmp_path, "a2cf", iterations=4, run_name="whole", ppo=ppo,
                              curriculum=MEAN_RULE), verbose=False)  # fmt: skip
    part = train(tiny_config(tmp_path, "a2cf", iterations=2, run_name="part", ppo=ppo,
                             curriculum=MEAN_RULE), verbose=False)  # fmt: skip
    log_before = read_jsonl(part.run_dir / CURRICULUM_LOG)
    assert log_before[1]["eta"] != log_before[0]["eta"]  # the bound moved before the "kill"
    resumed = train(TrainConfig(resume=str(part.run_dir), iterations=4), verbose=False)
    assert resumed.iterations_done == 4
    a, b = whole.metrics["iterations"], resumed.metrics["iterations"]
    assert [r["iteration"] for r in b] == [0, 1, 2, 3]
    for row_a, row_b in zip(a, b, strict=True):
        assert {k: row_a[k] for k in PLAIN_KEYS} == {k: row_b[k] for k in PLAIN_KEYS}, row_a[
            "iteration"
        ]
    assert read_jsonl(whole.run_dir / CURRICULUM_LOG) == read_jsonl(part.run_dir / CURRICULUM_LOG)
    wa = torch.load(whole.run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    wb = torch.load(part.run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
    for key, value in wa["actor_state_dict"].items():
        assert torch.equal(value, wb["actor_state_dict"][key]), key


def test_training_runs_rsl_rl_own_loop() -> None:
    """No copy of OnPolicyRunner.learn anywhere in rl/: the curriculum is an env event."""
    from pathlib import Path

    from rsl_rl.runners import OnPolicyRunner

    from rl.training.runner import A2CFRunner

    assert A2CFRunner.learn is OnPolicyRunner.learn
    sources = Path(__file__).resolve().parents[1].joinpath("rl").rglob("*.py")
    assert not [p for p in sources if "def learn(" in p.read_text()]


def test_resume_says_which_flags_it_does_not_apply(tmp_path, capsys) -> None:
    run = train(tiny_config(tmp_path, "a2cf", iterations=1), verbose=False).run_dir
    argv = ["train", "--resume", str(run), "--iterations", "2", "--env-num-envs", "8",
            "--ppo-learning-rate", "0.5", "--task-reward-weight", "alive=3"]  # fmt: skip
    assert cli_main(argv) == 0
    err = capsys.readouterr().err
    assert "not applied: --env-num-envs --ppo-learning-rate --task-reward-weight" in err
    saved = json.loads((run / "config.json").read_text())["train"]
    assert saved["env"]["num_envs"] == 4 and saved["ppo"]["learning_rate"] == 1e-3


def test_cli_task_and_env_flags_reach_the_run(tmp_path) -> None:
    argv = [
        "train", "--env-num-envs", "2", "--env-num-threads", "1", "--iterations", "1",
        "--num-steps-per-env", "4", "--out", str(tmp_path), "--run-name", "flags",
        "--ppo-num-mini-batches", "1", "--ppo-num-learning-epochs", "1", "--no-export-onnx",
        "--model-motion-hidden-dims", "8", "--model-critic-hidden-dims", "8",
        "--model-encoder-hidden-dims", "8", "--model-assist-hidden-dims", "8",
        "--task-pushes-velocity-xy-mps", "0.25", "--task-reward-weight", "upright=2",
        "--task-term-param", "tilted.max_tilt_rad=0.6", "--no-task-scene-link-collisions",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    config = json.loads((tmp_path / "flags" / "config.json").read_text())
    assert config["train"]["task_overrides"] == {
        "pushes.velocity_xy_mps": 0.25, "scene.link_collisions": False,
        "reward_weights": {"upright": 2.0}, "term_params": {"tilted": {"max_tilt_rad": 0.6}},
    }  # fmt: skip
    task = config["task"]
    assert task["pushes"]["velocity_xy_mps"] == 0.25 and not task["scene"]["link_collisions"]
    weights = {t["name"]: t["weight"] for t in task["rewards"]}
    assert weights["upright"] == 2.0 and weights["alive"] == 1.0
    bad = argv[:-3] + ["--task-term-param", "tilted.tilt=1", "--run-name", "bad"]
    assert cli_main(bad) == 2 and not (tmp_path / "bad").exists()


def test_eval_refuses_bad_sizes_and_keeps_eval_json(tmp_path, capsys) -> None:
    run = train(tiny_config(tmp_path, "baseline", iterations=1), verbose=False).run_dir
    (run / "eval.json").write_text('{"survival_fraction": 0.52}')
    assert cli_main(["eval", str(run), "--num-steps", "-5"]) == 2
    assert "--num-steps must be in [0, " in capsys.readouterr().err
    assert json.loads((run / "eval.json").read_text()) == {"survival_fraction": 0.52}


def test_half_created_and_damaged_runs_resume_or_say_what_to_do(tmp_path, capsys) -> None:
    """A run killed before its first checkpoint restarts from iteration 0 (same seed, same run);
    an unreadable last.pt falls back to the newest readable model_<k>.pt."""
    cfg = tiny_config(tmp_path, "a2cf", iterations=2, save_interval=1)
    whole = train(dataclasses.replace(cfg, run_name="whole"), verbose=False)
    run = train(dataclasses.replace(cfg, run_name="half"), verbose=False).run_dir
    for path in (run / CHECKPOINT_DIR).iterdir():
        path.unlink()
    # its logs show 2 iterations: starting it again would lose them, so it is refused
    with pytest.raises(ValueError, match="2 completed iterations logged but no checkpoint"):
        train(TrainConfig(resume=str(run), iterations=2), verbose=False)
    for name in ("metrics.jsonl", "metrics.json"):
        (run / name).unlink()  # now as if killed during iteration 0 (it logged nothing)
    again = train(TrainConfig(resume=str(run), iterations=2), verbose=False)
    assert "no checkpoint yet" in capsys.readouterr().err
    assert read_jsonl(run / CURRICULUM_LOG) == read_jsonl(whole.run_dir / CURRICULUM_LOG)
    assert [r["mean_step_reward"] for r in again.metrics["iterations"]] == [
        r["mean_step_reward"] for r in whole.metrics["iterations"]
    ]
    # a new run into the same folder is refused with what to do, and loses nothing
    assert cli_main(["train", "--out", str(tmp_path), "--run-name", "half"]) == 2
    assert "use --resume" in capsys.readouterr().err
    (run / CHECKPOINT_DIR / LAST_CHECKPOINT).write_bytes(b"PK\x03\x04 truncated")
    resumed = train(TrainConfig(resume=str(run), iterations=3), verbose=False)
    assert "resuming from model_2.pt" in capsys.readouterr().err
    assert resumed.iterations_done == 3
    for path in (run / CHECKPOINT_DIR).iterdir():
        path.write_bytes(b"")
    assert cli_main(["train", "--resume", str(run), "--iterations", "4"]) == 2
    assert "no readable checkpoint" in capsys.readouterr().err
    (run / "config.json").write_text("{")
    assert cli_main(["train", "--resume", str(run)]) == 2
    assert "config.json is not a valid run config" in capsys.readouterr().err


def test_eval_without_a_gl_driver_keeps_its_metrics(tmp_path, monkeypatch) -> None:
    """No offscreen GL (or no encoder): eval still writes its metrics and says why there is no
    video (fault injected where the renderer would fail)."""
    import rl.evaluation.policy
    from optimal_control.render import RenderUnavailableError

    run = train(tiny_config(tmp_path, "baseline", iterations=1), verbose=False).run_dir

    def no_gl(*args, **kwargs):
        raise RenderUnavailableError("MuJoCo offscreen rendering failed with MUJOCO_GL=egl")

    monkeypatch.setattr(rl.evaluation.policy, "render_qpos", no_gl)
    # past the up-front check (on a machine without GL that check refuses before the rollout)
    monkeypatch.setattr("optimal_control.render.check_offscreen_rendering", lambda: None)
    with pytest.warns(UserWarning, match="no video"):
        result = evaluate(run, EvalConfig(num_envs=2, num_steps=3, video=str(tmp_path / "v.mp4")))
    saved = json.loads((run / "eval.json").read_text())
    assert saved["video_note"].startswith("no video: MuJoCo offscreen rendering failed")
    assert "video" not in saved and saved["num_steps"] == 3 == result["num_steps"]


def test_eval_video_frames_carry_a_tracking_tasks_reference() -> None:
    """Env 0's video frames: a dance env starts on its reference frame (the ghost's first pose is
    the robot's), then the ghost follows the clip, one pose per frame; stand has no ghost."""
    from rl.envs.task_schema import quiet
    from rl.evaluation.policy import _VideoFrames
    from rl.tasks.registry import get_task, make_env

    env = make_env(quiet(get_task("dance")), 2, num_threads=1)
    try:
        env.command_gen.for_evaluation()  # from the first frame, as eval's video
        env.reset_envs(torch.arange(2))
        frames = _VideoFrames()
        frames.record(env)
        for _ in range(60):  # the dance stands still for its first second
            env.step(torch.zeros(2, env.num_actions))
            frames.record(env)
        now = env.command_gen.reference_qpos()
        assert env.command_gen.reference_duration_s(0) == pytest.approx(19.0)  # a video's length
    finally:
        env.close()
    ghost = frames.ghost_qpos()
    assert ghost is not None and ghost.shape == (61, 36) == np.asarray(frames.qpos).shape
    np.testing.assert_allclose(ghost[0], frames.qpos[0], atol=1e-9)
    np.testing.assert_array_equal(ghost[-1], now[0])
    assert np.abs(ghost[-1] - ghost[0]).max() > 1e-4  # the reference moved on
    env = make_env("stand", 1, num_threads=1)
    try:
        frames = _VideoFrames()
        frames.record(env)
        assert env.command_gen.reference_duration_s(0) is None
    finally:
        env.close()
    assert frames.ghost_qpos() is None and len(frames) == 1


def test_figures_are_written_atomically(tmp_path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from optimal_control.files import atomic_savefig

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = atomic_savefig(fig, tmp_path / "plot.png", dpi=50)
    plt.close(fig)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]  # no temporary left behind


_MODES = [pytest.param(m, marks=() if m == "a2cf" else pytest.mark.slow)
          for m in ("a2cf", "baseline", "no-pi", "no-id", "no-rm")]  # fmt: skip


@pytest.mark.parametrize("mode", _MODES)
@pytest.mark.parametrize("task", sorted(__import__("rl.tasks.registry", fromlist=["TASKS"]).TASKS))
def test_every_task_trains_in_every_mode(tmp_path, task: str, mode: str) -> None:
    """One iteration of every registered task in every mode (a2cf, with its alone envs, in the
    default suite; the others in the slow one): the walk tasks once crashed at their first alone
    episode (an alone measure without the curriculum's per-env starts)."""
    cfg = tiny_config(tmp_path, mode, task=task, iterations=1, export_onnx=False,
                      num_steps_per_env=4)  # fmt: skip
    result = train(cfg, verbose=False)
    assert result.iterations_done == 1


def test_the_walks_alone_envs_move_their_own_terrain_levels() -> None:
    from rl.tasks.registry import make_env

    env = make_env("walk", 4, num_threads=1)
    try:
        env.task_components.track_alone(8)
        alone = env.task_components.alone_skill
        assert alone is not None and alone.curriculum is env.task_components.skill
        state = env.env_state
        ids = torch.tensor([3])
        env.task_components.skill.levels[3] = 2
        alone.on_episodes_end(ids, torch.tensor([True]), torch.tensor([10]), state)
        assert alone.seen.tolist() == [False, False, False, True]
        assert alone.mean_level() == float(env.task_components.skill.levels[3])
        assert "Curriculum/terrain_level_alone" in alone.log()
    finally:
        env.close()


def test_a_learning_rate_stuck_at_the_adaptive_floor_is_detected() -> None:
    """walk-flat's 5 x 4 update at 128 x 24 samples kept rsl-rl's adaptive rate at 1e-5 from the
    first iteration on: the run warns (RunLogger) when the last 50 iterations sat there."""
    from rl.training.runner import ADAPTIVE_LR_FLOOR, learning_rate_floored

    stuck = [{"learning_rate": ADAPTIVE_LR_FLOOR * f} for f in (1.0, 1.5) * 25]
    assert learning_rate_floored(stuck)
    assert not learning_rate_floored(stuck[:-1])  # too few iterations to tell
    assert not learning_rate_floored(stuck[:-1] + [{"learning_rate": 3e-4}])


def test_eta_of_a_resumed_run_counts_the_whole_run(tmp_path, capsys) -> None:
    """A resumed run restores the whole run's logged time: its ETA must divide that time by all
    the iterations done, not by those since the resume (else 100x too long 100 iterations in)."""
    from rl.training.runner import RunLogger

    cfg = {"algorithm": {}, "num_steps_per_env": 24, "logger": "tensorboard"}
    logger = RunLogger(str(tmp_path), cfg, {}, 4, False, 1, 0, "cpu")
    logger.init_logging_writer()
    logger.tot_time = 990.0  # 99 iterations of 10 s before the resume
    # iteration 99, the first after a resume at 99, of 10 s: 100 of 200 left at 10 s each
    logger.log(99, 99, 200, 5.0, 5.0, {"surrogate": 0.0}, 1e-3, torch.ones(3), None)
    eta = capsys.readouterr().out.split("ETA:")[-1].split()[0]
    assert eta == "0:16:40"


@pytest.mark.parametrize("assist_in_ratio", ["while_helping", "always"])
def test_the_assist_head_rests_once_the_curriculum_turns_help_off(tmp_path, assist_in_ratio):
    """A 1-iteration anneal turns assistance off after the first update; from then on the
    default leaves the assist actions out of PPO's ratio and entropy (their std stays where it
    was), rsl-rl's joint action ("always") keeps widening it under the entropy bonus."""
    cfg = tiny_config(
        tmp_path, "a2cf", iterations=4, curriculum=CurriculumConfig(anneal_iterations=1),
        ppo=dataclasses.replace(TINY_PPO, assist_in_ratio=assist_in_ratio, entropy_coef=0.05),
    )  # fmt: skip
    run = train(cfg, verbose=False).run_dir

    def assist_std(k: int) -> torch.Tensor:
        state = torch.load(run / CHECKPOINT_DIR / f"model_{k}.pt", weights_only=False)
        return state["actor_state_dict"]["distribution.std_param"][29:]

    log = read_jsonl(run / CURRICULUM_LOG)
    assert [row["assist_enabled"] for row in log] == [False] * 4
    # iteration 2 on: no help (Adam's first moments of the assist head cleared at the switch)
    moved = bool((assist_std(4) != assist_std(1)).any())
    assert moved == (assist_in_ratio == "always")


@pytest.mark.parametrize("speed", [1.0, 0.25])
def test_eval_video_slow_motion_draws_every_step(tmp_path, speed: float) -> None:
    """--video-speed below 1 draws every control step and plays them slower (a flip's half
    second); real time draws every second step at 1 / (2 dt)."""
    import imageio.v2 as imageio

    from optimal_control.render import RenderUnavailableError
    from rl.evaluation.policy import render_qpos
    from robots import g1

    pose = np.concatenate([[0.0, 0.0, 0.8, 1.0, 0.0, 0.0, 0.0], g1.STAND_JOINT_POS_RAD])
    qpos = np.tile(pose, (8, 1))
    try:
        path = render_qpos(qpos, 0.02, str(tmp_path / "v.mp4"), "stand", ghost_qpos=None,
                            ghost_side_m=0.0, speed=speed)  # fmt: skip
    except RenderUnavailableError as err:
        pytest.skip(f"no offscreen rendering here: {err}")
    reader = imageio.get_reader(path)
    frames, fps = reader.count_frames(), reader.get_meta_data()["fps"]
    assert (frames, fps) == ((4, 25.0) if speed == 1.0 else (8, 12.5))
    with pytest.raises(ValueError, match="--video-speed"):
        EvalConfig(video_speed=0.0)
