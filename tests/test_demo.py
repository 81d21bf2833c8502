"""``a2cf-mb demo``: the live progress (log parsing, status lines, the board, child lanes), the
summary and its verdict, the output-folder checks, and the whole demo at a tiny budget."""

from __future__ import annotations

import dataclasses
import io
import json
import sys
from pathlib import Path

import pytest

from a2cf_mb import demo as demo_module
from a2cf_mb.cli import DEBUG_ENV, main
from a2cf_mb.demo import DemoConfig, check_output, train_arguments
from a2cf_mb.demo_report import (
    A2CF,
    BASELINE,
    build_summary,
    compare,
    render_report,
    run_entry,
    verdict,
)
from a2cf_mb.progress import (
    Stage,
    StageFailedError,
    StatusBoard,
    TrainFollower,
    clock_str,
    format_train_status,
    run_lanes,
)

# The end of one rsl-rl iteration block as rsl-rl 5.5 prints it (header in bold).
METRICS_ROW = {"iteration": 119, "completed": 120, "total_iterations": 320,
               "total_env_steps": 368_640, "mean_episode_length": 82.41}  # fmt: skip
"""A line of the runner's metrics.jsonl."""
ALONE_ROW = {
    "iteration": 96, "env_steps": 294912, "survival_fraction": 0.25,
    "task_metrics": {"skill_error_rad": 0.8125, "joint_all_rad": 0.12},
}  # fmt: skip
CURRICULUM_ROW = {
    "iteration": 119,
    "eta": [[30.0, 40.0, 0.0, 5.0, 12.0, 0.0]],
    "applied_force_n": 21.5,
}


class FakeClock:
    """A clock the test moves by hand [s]."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _fake_run_folder(run_dir: Path) -> None:
    run_dir.mkdir(parents=True)
    (run_dir / "config.json").write_text("{}")
    (run_dir / "curriculum.jsonl").write_text(json.dumps(CURRICULUM_ROW) + "\n")
    (run_dir / "evals.jsonl").write_text(json.dumps(ALONE_ROW) + "\n")


# ------------------------------------------------------------------------------- progress
def _append_metrics(run_dir: Path, **row) -> None:
    with (run_dir / "metrics.jsonl").open("a") as f:
        f.write(json.dumps({**METRICS_ROW, **row}) + "\n")


def test_follower_reads_iteration_steps_length_bound_and_eta(tmp_path):
    run_dir, clock = tmp_path / "run", FakeClock()
    follower = TrainFollower(run_dir, total=320, warmstart=True, clock=clock)
    assert follower.poll().phase == "starting"
    _fake_run_folder(run_dir)
    assert follower.poll().phase == "warm start"  # config.json written, warmstart.json not yet
    (run_dir / "warmstart.json").write_text("{}")
    assert follower.poll().phase == "first iteration"
    with (run_dir / "metrics.jsonl").open("a") as f:  # a line being written: not read yet
        f.write(json.dumps(METRICS_ROW)[:40])
    assert follower.poll().phase == "first iteration"
    with (run_dir / "metrics.jsonl").open("a") as f:
        f.write(json.dumps(METRICS_ROW)[40:] + "\n")
    snap = follower.poll()
    assert (snap.completed, snap.total, snap.env_steps) == (120, 320, 368_640)
    assert snap.mean_episode_length == pytest.approx(82.41)
    assert (snap.bound_force_n, snap.bound_torque_nm) == (pytest.approx(50.0), pytest.approx(13.0))
    assert snap.alone == ALONE_ROW
    assert snap.eta_s is None  # one iteration seen: no rate yet
    clock.now = 20.0
    _append_metrics(run_dir, completed=130)
    snap = follower.poll()
    assert snap.completed == 130
    assert snap.eta_s == pytest.approx(2.0 * 190)  # 10 iterations in 20 s, 190 to go


def test_status_line_says_iteration_steps_length_bound_alone_and_eta(tmp_path):
    run_dir = tmp_path / "run"
    _fake_run_folder(run_dir)
    _append_metrics(run_dir)
    follower = TrainFollower(run_dir, total=320)
    snap = follower.poll()
    snap.eta_s = 280.0
    line = format_train_status(A2CF, snap, 400.0, "skill_error_rad")
    for needle in ("a2cf_warm", "6:40", "120/320 it", "368,640 env steps", "ep len  82",
                   "bound 50 N 13 Nm", "alone@96: survival 25%, skill_error_rad 0.812",
                   "ETA 4:40"):  # fmt: skip
        assert needle in line, line
    assert line.index("ETA") < line.index("alone@")  # a narrow terminal cuts the end
    starting = format_train_status(BASELINE, TrainFollower(tmp_path / "x", 5).snapshot, 3, "m")
    assert "starting" in starting and "ETA" not in starting
    assert clock_str(3725) == "1:02:05" and clock_str(59.6) == "1:00"


def test_board_prints_every_interval_off_a_terminal_and_redraws_on_one():
    clock, plain = FakeClock(), io.StringIO()
    board = StatusBoard(plain, tty=False, plain_interval_s=30.0, clock=clock)
    board.show(["run a 1/3"])
    clock.now = 29.0
    board.show(["run a 2/3"])
    assert plain.getvalue() == ""  # not yet due
    clock.now = 31.0
    board.show(["run a 3/3", "run b 1/3"])
    board.message("run a: done")
    assert plain.getvalue() == "  run a 3/3\n  run b 1/3\nrun a: done\n"
    assert "\x1b" not in plain.getvalue()

    screen = io.StringIO()
    board = StatusBoard(screen, tty=True, refresh_s=2.0, clock=clock)
    board.show(["a 1", "b 1"], force=True)
    board.message("a: started")  # printed above the block, which is drawn again below it
    clock.now += 2.0
    board.show(["a 2", "b 2"])
    board.close()
    assert screen.getvalue() == (
        "a 1\nb 1\n" "\x1b[2F\x1b[Ja: started\na 1\nb 1\n" "\x1b[2F\x1b[Ja 2\nb 2\n" "\x1b[2F\x1b[J"
    )  # fmt: skip


def _stage(tmp_path: Path, label: str, code: str) -> Stage:
    return Stage(
        label=label,
        argv=[sys.executable, "-c", code],
        log=tmp_path / f"{label}.log",
        status=lambda t: f"{label} {t:.0f}",
        done=lambda t: f"{label}: done",
    )


def test_lanes_run_side_by_side_in_order_and_a_failure_stops_them_with_the_log_tail(tmp_path):
    out = io.StringIO()
    ok = [_stage(tmp_path, "a1", "print('a1 ran')"), _stage(tmp_path, "a2", "print('a2 ran')")]
    times = run_lanes([ok, [_stage(tmp_path, "b1", "pass")]], StatusBoard(out, tty=False))
    assert set(times) == {"a1", "a2", "b1"}
    assert out.getvalue().index("a1: done") < out.getvalue().index("a2: started")
    log = (tmp_path / "a2.log").read_text()
    assert log.startswith("$ ") and "a2 ran" in log  # the command, then its output

    slow = [_stage(tmp_path, "slow", "import time; time.sleep(60)"), _stage(tmp_path, "next", "")]
    failing = [_stage(tmp_path, "bad", "import sys; print('boom: bad input'); sys.exit(3)")]
    with pytest.raises(StageFailedError) as err:
        run_lanes([slow, failing], StatusBoard(io.StringIO(), tty=False), poll_s=0.05)
    text = str(err.value)
    assert "bad failed (exit code 3)" in text and "boom: bad input" in text
    assert str(tmp_path / "bad.log") in text
    assert not (tmp_path / "next.log").exists()  # the other lane was stopped, not continued


# -------------------------------------------------------------------------------- summary
def _run_entry(name: str, skill_error: float, survival: float, warm: bool) -> dict:
    evaluation = {
        "survival_fraction": survival, "mean_return": 50.0, "mean_episode_length_steps": 300.0,
        "num_envs": 32, "target_reached": skill_error <= 0.16,
        "task_metrics": {"skill_error_rad": skill_error, "joint_all_rad": 0.1,
                         "plot": f"/x/demo/runs/{name}/eval_dance.png"},
        "sim2sim": {"survival_fraction": survival / 2, "mean_return": 40.0,
                    "mean_episode_length_steps": 250.0},
        "video_note": "no video: EGL missing",
    }  # fmt: skip
    metrics = {
        "iterations_done": 320, "mean_iteration_time_s": 1.4,
        "iterations": [{"env_steps": 3072}] * 320,
        "alone_evaluations": [{}] * 10, "alone_target_held_at": None,
    }  # fmt: skip
    warmstart = {
        "config": {"rounds": 3, "steps_per_round": 48}, "coach": "the oracle's coach",
        "held_out_fit": {"fx": {"r2": 0.75}},
    }  # fmt: skip
    return run_entry(
        name=name, command=f"a2cf-mb train --run-name {name}",
        config={"mode": "a2cf" if warm else "baseline", "num_steps_per_env": 24,
                "env": {"num_envs": 128}},
        metrics=metrics, evaluation=evaluation, warmstart=warmstart if warm else None,
        train_wall_s=470.0, eval_wall_s=55.0, out=Path("/x/demo"), metric="skill_error_rad",
    )  # fmt: skip


def _summary(baseline_error: float, a2cf_error: float, survival: float = 0.5) -> dict:
    runs = {
        BASELINE: _run_entry(BASELINE, baseline_error, survival, warm=False),
        A2CF: _run_entry(A2CF, a2cf_error, survival, warm=True),
    }
    target = {
        "describe": "survival >= 0 and skill_error_rad <= 0.16", "metric": "skill_error_rad",
        "max_metric": 0.16, "min_survival": 0.0, "fall_error": 1.0,
        "one_episode_of_the_mean": 1 / 32, "episode_length_s": 10.0,
    }  # fmt: skip
    oracle = {
        "command": "a2cf-mb solve-dance --out OUT/oracle", "wall_time_s": 7.0,
        "phases": ["dance"], "eta0": [[16.9, 38.4, 5.0, 50.6, 27.5, 21.7]],
        "eta0_frame": "heading", "novice_model": "alpha 0.5", "plots": [],
    }  # fmt: skip
    config = {
        **dataclasses.asdict(DemoConfig()),
        "eval_interval": 32,
        "a2cf_variant_flags": ["--x", "1"],
    }
    summary = build_summary("dance", config, oracle, runs, target, wall_time_s=600.0)
    summary["figure"] = "demo_curves.png"
    return summary


def test_run_entry_holds_the_evaluation_alone_steps_times_and_relative_paths():
    entry = _run_entry(A2CF, 0.4, 0.75, warm=True)
    assert entry["env_steps"] == 320 * 3072 and entry["run_dir"] == "runs/a2cf_warm"
    assert entry["alone"]["skill_error_rad"] == 0.4  # the skill metric, at the top
    assert entry["alone"]["survival_fraction"] == 0.75
    assert entry["alone"]["task_metrics"]["plot"] == "runs/a2cf_warm/eval_dance.png"
    assert entry["sim2sim"]["survival_fraction"] == 0.375
    assert entry["warmstart"]["env_steps"] == 3 * 48 * 128
    assert (entry["train_wall_time_s"], entry["eval_wall_time_s"]) == (470.0, 55.0)
    assert _run_entry(BASELINE, 0.4, 0.75, warm=False)["warmstart"] is None


def test_the_verdict_names_the_run_ahead_by_how_much_and_at_which_budget():
    summary = _summary(baseline_error=0.9, a2cf_error=0.4)
    assert summary["comparison"]["ahead"] == A2CF
    assert summary["comparison"]["by"] == pytest.approx(0.5)
    text = verdict(summary)
    assert "a2cf_warm is ahead of baseline" in text and "0.500 lower" in text
    assert "983,040 env steps each" in text and "target <= 0.16" in text
    assert compare(summary["runs"], "skill_error_rad")["ahead"] == A2CF
    behind = verdict(_summary(baseline_error=0.3, a2cf_error=0.35))
    assert behind.startswith("baseline is ahead of a2cf_warm") and "0.050 lower" in behind
    level = verdict(_summary(baseline_error=1.0, a2cf_error=1.0, survival=0.0))
    assert level.startswith("Neither run is ahead") and "fell in every evaluation episode" in level


def test_the_verdict_reads_a_difference_against_the_seed_spread():
    summary = _summary(baseline_error=0.9, a2cf_error=0.4)
    spread = {"metric": "skill_error_rad", "values": {"s0": 0.3, "s1": 0.9, "s2": 0.5},
              "env_steps": 983040, "source": "docs/results/track_learn/seed_spread.json"}  # fmt: skip
    summary["seed_spread"] = spread
    assert "inside that spread, so it is noise between seeds" in verdict(summary)
    report = render_report(summary, Path("/x/demo"))
    assert "s0 0.300, s1 0.900, s2 0.500 at 983,040 env steps" in report
    summary["seed_spread"] = {**spread, "values": {"s0": 0.30, "s1": 0.35}}
    assert "larger than that spread" in verdict(summary)
    summary["seed_spread"] = {**spread, "metric": "tracking_score"}  # another metric: not used
    assert "spread" not in verdict(summary)


def test_report_states_budget_flags_numbers_and_what_a_longer_run_gives():
    report = render_report(_summary(baseline_error=0.9, a2cf_error=0.4), Path("/x/demo"))
    for needle in ("## 1. The oracle", "## 2. Training", "## 3. The motion policies alone",
                   "## 4. What this shows", "`--x 1`", "18,432 env steps", "983,040",
                   "| `a2cf_warm` | 50% | 0.400 |", "no video: EGL missing",
                   "a2cf_warm is ahead of baseline", "One seed and one budget", "0.031",
                   "--iterations 1600", "4,915,200 env steps per run", "37.3 min",
                   "![curves](demo_curves.png)"):  # fmt: skip
        assert needle in report, needle


# ------------------------------------------------------------------------ inputs and errors
def test_bad_output_folders_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    file = tmp_path / "file"
    file.write_text("x")
    with pytest.raises(ValueError, match="is a file"):
        check_output(file, overwrite=True)
    earlier = tmp_path / "earlier"
    (earlier / "runs").mkdir(parents=True)
    (earlier / "report.md").write_text("old")
    assert main(["demo", "--out", str(earlier), "--no-video"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    check_output(earlier, overwrite=True)  # an earlier demo's output may be replaced
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    assert main(["demo", "--out", str(mine), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "thesis.tex" in err and "choose another --out" in err
    assert (mine / "thesis.tex").read_text() == "precious"
    assert main(["demo", "--iterations", "0", "--out", str(tmp_path / "new")]) == 2
    assert "--iterations must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_a_bad_variant_flag_fails_in_seconds_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    monkeypatch.setattr(demo_module, "A2CF_VARIANT_FLAGS", ("--curriculum-no-such-flag", "1"))
    assert main(["demo", "--out", str(tmp_path / "d")]) == 2
    assert "--curriculum-no-such-flag" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_train_commands_share_seed_envs_budget_and_differ_in_mode_and_warm_start(tmp_path):
    cfg = DemoConfig(task="dance", iterations=100, num_envs=64, seed=3, evals=4)
    base = train_arguments(cfg, BASELINE, tmp_path)
    a2cf = train_arguments(cfg, A2CF, tmp_path)
    assert base[: base.index("--run-name")] == a2cf[: a2cf.index("--run-name")]
    for flag, value in (("--iterations", "100"), ("--num-envs", "64"), ("--seed", "3"),
                        ("--eval-interval", "25"), ("--torch-threads", "1"),
                        ("--env-num-threads", "1")):  # fmt: skip
        assert base[base.index(flag) + 1] == value
    assert base[base.index("--mode") + 1] == "baseline"
    assert a2cf[a2cf.index("--mode") + 1] == "a2cf"
    assert a2cf[a2cf.index("--warmstart") + 1] == str(tmp_path / "oracle")
    flags = list(demo_module.A2CF_VARIANT_FLAGS)
    assert a2cf[a2cf.index("--warmstart") + 2 :] == flags
    recipe = list(demo_module.STORIES["dance"].recipe_flags)  # both runs: the same update
    for args in (base, a2cf):
        assert args[args.index(recipe[0]) : args.index(recipe[0]) + len(recipe)] == recipe
    # the default story: stand, its A2CF run warm-started from the posture coach, no oracle
    stand = train_arguments(DemoConfig(), A2CF, tmp_path)
    assert stand[stand.index("--task") + 1] == "stand"
    assert stand[stand.index("--warmstart") + 1] == "posture"
    with pytest.raises(ValueError, match="demo --task 'walk': choose one of stand, dance"):
        DemoConfig(task="walk")


def test_a_failed_stage_is_one_message_with_its_log(capsys, monkeypatch):
    def fail(cfg):
        raise StageFailedError(
            "train baseline failed (exit code 1); its log x.log ends with:\nboom"
        )

    monkeypatch.setattr(demo_module, "run_demo", fail)
    assert main(["demo"]) == 1
    err = capsys.readouterr().err
    assert "a2cf-mb demo: error: train baseline failed" in err and "boom" in err
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- end to end
def _run_tiny_demo(out: Path, *extra: str) -> None:
    argv = ["demo", "--iterations", "2", "--num-envs", "8", "--evals", "1", "--eval-envs", "2",
            "--out", str(out), *extra]  # fmt: skip
    assert main(argv) == 0


def test_tiny_stand_demo_end_to_end(tmp_path, capsys):
    """The default story at 2 iterations of 8 envs, no video: no oracle stage, the A2CF run
    warm-started from the posture coach, runs compared by survival alone."""
    out = tmp_path / "demo"
    _run_tiny_demo(out, "--no-video")
    printed = capsys.readouterr().out
    assert "[1/3] oracle" not in printed and "warm-started from the posture coach" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["task"] == "stand" and summary["oracle"] is None
    assert summary["comparison"]["metric"] == "survival_fraction"
    assert summary["comparison"]["higher_is_better"] is True
    assert summary["runs"][A2CF]["warmstart"]["env_steps"] > 0
    for run in summary["runs"].values():
        assert (out / run["run_dir"] / "policy.onnx").is_file()
    report = (out / "report.md").read_text()
    for needle in ("warm-started from the posture coach", "## 1. The help", "posture coach",
                   "| stand | 40.0 | 40.0 | 10.0 |", "--mode a2cf --warmstart posture",
                   "episode length [steps]", "## 4. What this shows",
                   "docs/results/stand_judge"):  # fmt: skip
        assert needle in report, needle
    assert (out / "demo_curves.png").stat().st_size > 0


def test_tiny_demo_end_to_end(tmp_path, capsys):
    """The dance's story at 2 iterations of 8 envs, no video (about half a minute on 2 free
    cores): the oracle, then the runs warm-started from it."""
    out = tmp_path / "demo"
    _run_tiny_demo(out, "--no-video", "--task", "dance")
    printed = capsys.readouterr().out
    for needle in ("[1/3] oracle: done", "[2/3] train baseline: done", "[2/3] train a2cf_warm: done",
                   "[3/3] eval baseline: done", "[3/3] eval a2cf_warm: done", "demo done in"):  # fmt: skip
        assert needle in printed, needle
    summary = json.loads((out / "summary.json").read_text())
    assert summary["task"] == "dance"
    assert summary["config"]["a2cf_variant_flags"] == list(demo_module.A2CF_VARIANT_FLAGS)
    assert len(summary["oracle"]["eta0"]) == len(summary["oracle"]["phases"]) == 1
    for name in (BASELINE, A2CF):
        run = summary["runs"][name]
        assert (out / run["run_dir"] / "policy.onnx").is_file()
        assert run["env_steps"] == 2 * 8 * 24 and run["iterations"] == 2
        assert 0.0 <= run["alone"]["survival_fraction"] <= 1.0
        assert isinstance(run["alone"]["tracking_score"], float)
        assert run["alone"]["task_metrics"]["statue_joint_error_rad"] > 0.0
        assert "survival_fraction" in run["sim2sim"]
        assert run["alone_during_training"]["evaluations"] == 1
        assert run["train_wall_time_s"] > 0 and run["eval_wall_time_s"] > 0
        assert (out / "logs" / f"train_{name}.log").is_file()
    assert summary["runs"][A2CF]["warmstart"]["env_steps"] > 0
    assert summary["comparison"]["metric"] == "tracking_score"
    report = (out / "report.md").read_text()
    for needle in ("## 1. The oracle", "## 3. The motion policies alone", "sim2sim",
                   "| `baseline` |", "| `a2cf_warm` |", "--mode a2cf --warmstart OUT/oracle",
                   "## 4. What this shows", "--iterations 1600", "(statue "):  # fmt: skip
        assert needle in report, needle
    assert (out / "demo_curves.png").stat().st_size > 0


@pytest.mark.slow
def test_demo_with_videos(tmp_path):
    """With videos (MUJOCO_GL=egl): each evaluation has a video or says why not."""
    out = tmp_path / "demo"
    _run_tiny_demo(out, "--eval-envs", "4")
    summary = json.loads((out / "summary.json").read_text())
    for run in summary["runs"].values():
        assert (run["video"] and (out / run["video"]).stat().st_size > 0) or run["video_note"]
    # the zoo first: each learned skill's video and contact sheet, linked from the report
    for skill, entry in summary["zoo"].items():
        assert (out / entry["video"]).stat().st_size > 0, skill
        assert (out / entry["contact_sheet"]).stat().st_size > 0, skill
    if summary["zoo"]:
        assert "## 0. What the toolkit has learned" in (out / "report.md").read_text()
        assert (out / "zoo" / "zoo.png").is_file()
