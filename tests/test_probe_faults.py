"""The probe of issue 56 as the project's suite: faults a careful user still trips over.

Each case is run as a user would (``a2cf-mb ...`` in this process, or a subprocess where the
environment matters) against one tiny finished run made once per test session: a resume that
could lose a run, numbers outside any sense, the environment (``MUJOCO_GL``, a video path),
and one-liners that named the wrong flag or none. A refusal is exit code 2 and one line naming
the input and what to do, and leaves every byte of the run folder as it was. The default suite
runs the issue's cases; the whole flag matrix (every numeric flag of ``train``, ``eval`` and
``eval-curve`` at values outside any sense) is ``@pytest.mark.slow``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from test_training import tiny_config

from a2cf_mb.cli import DEBUG_ENV, TRACEBACK_DIR_ENV, build_parser, main
from rl.evaluation.config import AloneEvalConfig
from rl.runs.folder import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    EVAL_FILE,
    LOCK_FILE,
    METRICS_FILE,
    METRICS_LOG,
    RunFolderLock,
    StaleLockWarning,
)
from rl.training.runner import train

SMALL_EVAL = ("--num-envs", "2", "--num-steps", "3")
ITERATIONS = 4


@pytest.fixture(autouse=True)
def as_a_user(monkeypatch, tmp_path):
    """No A2CF_DEBUG; tracebacks saved under the test's folder."""
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    monkeypatch.setenv(TRACEBACK_DIR_ENV, str(tmp_path / "tracebacks"))


@pytest.fixture(scope="session")
def probe_run(tmp_path_factory) -> Path:
    """A finished 4-iteration run (4 envs x 8 steps, checkpoints at 2 and 4, ONNX exported), made
    once per session; cases copy it and never change it."""
    root = tmp_path_factory.mktemp("probe")
    cfg = tiny_config(
        root, "a2cf", iterations=ITERATIONS, save_interval=2, eval=AloneEvalConfig(interval=0)
    )
    return train(cfg, verbose=False).run_dir


@pytest.fixture
def run(probe_run, tmp_path) -> Path:
    """A copy of the probe run this case may damage."""
    return Path(shutil.copytree(probe_run, tmp_path / "run"))


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def run_cli(capsys, *args: object) -> tuple[int, str]:
    """``a2cf-mb ARGS`` in this process: exit code and stderr."""
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def assert_one_line(err: str, *needles: str) -> None:
    """One non-empty line on stderr, no traceback, naming every needle."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err and "unexpected error" not in err, err
    for needle in needles:
        assert needle in err, err


def assert_refused(capsys, run: Path | None, *args: object, needles: tuple[str, ...]) -> str:
    """The command exits 2 with one line naming ``needles``; ``run`` unchanged."""
    before = snapshot(run) if run is not None else None
    code, err = run_cli(capsys, *args)
    assert code == 2, err
    assert_one_line(err, *needles)
    if run is not None:
        assert snapshot(run) == before
    return err


# ------------------------------------------------------------------ a resume never destroys
def test_a_run_with_rows_but_no_checkpoint_is_refused_not_restarted(capsys, run):
    shutil.rmtree(run / CHECKPOINT_DIR)
    (run / CHECKPOINT_DIR).mkdir()
    err = assert_refused(
        capsys, run, "train", "--resume", run,
        needles=(f"{ITERATIONS} completed iterations logged", "no checkpoint", "restore",
                 "new run"),
    )  # fmt: skip
    assert "from iteration 0" not in err
    # flags a resume would not apply: still the one line of the refusal, no warning before it
    assert_refused(capsys, run, "train", "--resume", run, "--ppo-lam", "0.9",
                   needles=("no checkpoint", "restore"))  # fmt: skip


@pytest.mark.parametrize("use_onnx", ["--use-onnx", "--no-use-onnx"])
def test_eval_of_a_run_without_checkpoints_does_not_recommend_a_resume(capsys, run, use_onnx):
    shutil.rmtree(run / CHECKPOINT_DIR)
    err = assert_refused(
        capsys, run, "eval", use_onnx, *SMALL_EVAL, run, needles=("no checkpoint", "restore")
    )
    assert "--resume" not in err


@pytest.mark.parametrize("iterations", [1, ITERATIONS - 1])
def test_a_resume_to_fewer_iterations_than_done_is_refused(capsys, run, iterations):
    assert_refused(
        capsys, run, "train", "--resume", run, "--iterations", iterations,
        needles=(f"--iterations {iterations}", f"{ITERATIONS} iterations", "new run"),
    )  # fmt: skip


def test_a_resume_checks_the_disk_before_it_writes(capsys, monkeypatch, run):
    usage = shutil.disk_usage(run)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=4096))
    assert_refused(
        capsys, run, "train", "--resume", run, needles=("free", "the run folder is unchanged")
    )


def test_a_resume_checks_the_file_size_limit_before_it_writes(capsys, run):
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, hard))
    try:
        code, err = run_cli(capsys, "train", "--resume", run, "--iterations", ITERATIONS + 1)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert code == 2, err
    assert_one_line(err, "ulimit -f", "the run folder is unchanged")


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores permission bits")
def test_a_resume_of_a_read_only_run_folder_is_refused_unchanged(capsys, run):
    before = snapshot(run)
    run.chmod(0o555)
    try:
        code, err = run_cli(capsys, "train", "--resume", run, "--iterations", ITERATIONS + 1)
    finally:
        run.chmod(0o755)
    assert code == 2
    assert_one_line(err, str(run), "writable")
    assert snapshot(run) == before


def test_a_run_killed_in_its_first_iteration_still_starts_again(run):
    """No logged iteration, no checkpoint: nothing to lose, the resume starts from iteration 0
    (checked up to the choice of the start point, without training)."""
    from rl.runs.folder import start_point
    from rl.training.config import TrainConfig

    for name in (CHECKPOINT_DIR,):
        shutil.rmtree(run / name)
    for name in (METRICS_LOG, METRICS_FILE):
        (run / name).unlink()
    start = start_point(TrainConfig(resume=str(run), iterations=ITERATIONS), run)
    assert start.checkpoint is None


# ------------------------------------------------------------------ every number has a sense
# (command, flag, value): each refused by the flag the user typed, before anything is written
ISSUE_NUMBERS = [
    ("train", "--task-target-min-survival", "1e30"),
    ("train", "--task-target-min-survival", "-1"),
    ("train", "--task-pushes-velocity-xy-mps", "1e30"),
    ("train", "--task-initial-state-joint-pos-noise-rad", "-1"),
    ("train", "--task-initial-state-base-vel-noise", "-1"),
    ("train", "--task-initial-state-joint-pos-noise-rad", "1e30"),
    ("train", "--task-initial-state-base-vel-noise", "1e30"),
    ("train", "--ppo-init-noise-std", "1e30"),
    ("train", "--ppo-assist-init-noise-std", "1e30"),
    ("train", "--ppo-entropy-coef", "1e30"),
    ("train", "--ppo-value-loss-coef", "1e30"),
    ("train", "--ppo-desired-kl", "1e30"),
    ("train", "--model-vae-kl-weight", "1e30"),
    ("train", "--model-vae-velocity-weight", "1e30"),
    ("train", "--task-less-assist-weight", "1e30"),
    ("train", "--curriculum-less-assist-progress", "1e30"),
    ("train", "--curriculum-skill-learned-progress", "1e30"),
    ("train", "--task-pushes-interval-range-s", "0"),
    ("train", "--task-pushes-interval-range-s", "-1"),
    ("train", "--task-pushes-interval-range-s", "1e30"),
    ("train", "--task-randomization-friction-range", "0"),
    ("train", "--task-randomization-friction-range", "-1"),
    ("train", "--task-randomization-friction-range", "1e30"),
    ("train", "--task-episode-length-s", "1e30"),
    ("train", "--iterations", "10000000000"),
    ("train", "--save-interval", "10000000000"),
    ("eval", "--video-min-s", "-1"),
    ("eval", "--video-min-s", "1e30"),
    ("eval", "--seed", "-1"),
    ("eval", "--num-envs", "0"),
    ("eval-curve", "--num-envs", "0"),
    ("eval-curve", "--seed", "-1"),
    ("eval-curve", "--every-iterations", "0"),
]


def command_line(command: str, flag: str, values: list[str], run: Path, out: Path) -> list:
    """The command line of one numeric case (train writes under ``out``, eval reads ``run``)."""
    if command == "train":
        return ["train", "--out", out, "--run-name", "r", flag, *values]
    if command.startswith("solve-"):
        return [command, "--out", out, "--no-video", flag, *values]
    extra = ["--video", out / "v.mp4"] if flag.startswith("--video-") else []
    return [command, run, *extra, flag, *values]


@pytest.mark.parametrize(("command", "flag", "value"), ISSUE_NUMBERS)
def test_a_number_out_of_sense_is_refused_by_the_flag_typed(
    capsys, probe_run, tmp_path, command, flag, value
):
    out = tmp_path / "out"
    before = snapshot(probe_run)
    code, err = run_cli(capsys, *command_line(command, flag, [value], probe_run, out))
    assert code == 2, err
    assert_one_line(err, f"error: {flag} ")
    assert not out.exists()
    assert snapshot(probe_run) == before


def test_a_pair_flag_says_the_form_and_the_bounds(capsys, tmp_path):
    out = tmp_path / "out"
    for values in (["3", "1"], ["0", "1"], ["1", "1e30"]):
        code, err = run_cli(
            capsys, "train", "--out", out, "--task-pushes-interval-range-s", *values
        )
        assert code == 2
        assert_one_line(err, "--task-pushes-interval-range-s", "two numbers LOW HIGH", "(0, 3600]")
    assert not out.exists()


def numeric_flags(command: str) -> list[tuple[str, str]]:
    """(flag, kind) of every numeric option of ``command`` (kind: "int" or "float")."""
    root = build_parser(command)
    sub = next(a for a in root._actions if isinstance(a, argparse._SubParsersAction))
    flags = []
    for action in sub.choices[command]._actions:
        kind = getattr(action.type, "__name__", "")
        if action.option_strings and kind in ("int", "finite_float"):
            flags.append((action.option_strings[0], "int" if kind == "int" else "float"))
    return flags


NONSENSE = {"float": ("1e30", "-1e30", "nan", "inf"), "int": ("10000000000", "-10000000000", "nan")}
MATRIX = [
    pytest.param(command, flag, value, id=f"{command} {flag}={value}")
    for command in ("train", "eval", "eval-curve", "solve-walk", "solve-dance")
    for flag, kind in numeric_flags(command)
    if flag != "--iterations" or command == "train"  # eval-curve's K: a checkpoint's name
    for value in NONSENSE[kind]
]


@pytest.mark.slow
@pytest.mark.parametrize(("command", "flag", "value"), MATRIX)
def test_every_numeric_flag_refuses_nonsense(capsys, probe_run, tmp_path, command, flag, value):
    out = tmp_path / "out"
    code, err = run_cli(capsys, *command_line(command, flag, [value], probe_run, out))
    assert code == 2, err
    assert_one_line(err, flag)
    assert not out.exists()


# ------------------------------------------------------------------ the environment, up front
def cli_subprocess(*args: object, **env: str) -> subprocess.CompletedProcess:
    """``python -m a2cf_mb ARGS`` with ``env`` added to the environment."""
    return subprocess.run(
        [sys.executable, "-m", "a2cf_mb", *map(str, args)],
        env={**os.environ, DEBUG_ENV: "0", **env},
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.parametrize(
    "args",
    [["train", "--iterations", "1", "--out", "OUT"], ["eval", "RUN"],
     ["eval", "RUN", "--video", "OUT/v.mp4"], ["solve-dance", "--out", "OUT"]],
    ids=["train", "eval", "eval-video", "solve-dance"],
)  # fmt: skip
def test_a_mujoco_gl_that_names_no_backend_is_one_line(probe_run, tmp_path, args):
    out = tmp_path / "out"
    args = [a.replace("RUN", str(probe_run)).replace("OUT", str(out)) for a in args]
    before = snapshot(probe_run)
    done = cli_subprocess(*args, MUJOCO_GL="bogus")
    assert done.returncode == 2, done.stderr
    assert_one_line(done.stderr, f"a2cf-mb {args[0]}: error", "MUJOCO_GL=bogus", "MUJOCO_GL=egl")
    assert snapshot(probe_run) == before
    assert not out.exists()


def osmesa_loads() -> bool:
    """Whether MuJoCo imports with MUJOCO_GL=osmesa here (an OSMesa library is installed)."""
    code = "import mujoco"
    env = {**os.environ, "MUJOCO_GL": "osmesa"}
    return (
        subprocess.run([sys.executable, "-c", code], env=env, capture_output=True).returncode == 0
    )


@pytest.mark.parametrize("command", ["eval", "solve-dance"])
def test_a_gl_backend_that_cannot_load_is_one_line_before_any_work(run, tmp_path, command):
    if osmesa_loads():
        pytest.skip("OSMesa is installed here: MUJOCO_GL=osmesa renders")
    before = snapshot(run)
    args = ["eval", run, "--video", tmp_path / "v.mp4", *SMALL_EVAL] if command == "eval" else [
        "solve-dance", "--out", tmp_path / "art"]  # fmt: skip
    done = cli_subprocess(*args, MUJOCO_GL="osmesa")
    assert done.returncode == 2, done.stderr
    assert_one_line(done.stderr, "MUJOCO_GL=osmesa", "libosmesa6")
    assert snapshot(run) == before
    assert not (tmp_path / "art").exists()


def test_a_video_path_that_is_a_folder_is_one_line_before_the_rollout(capsys, run, tmp_path):
    folder = tmp_path / "video.mp4"
    folder.mkdir()
    assert_refused(capsys, run, "eval", run, *SMALL_EVAL, "--video", folder,
                   needles=(f"--video {folder} is a folder", "file name"))  # fmt: skip
    assert not (run / EVAL_FILE).exists()


def test_a_renderer_that_cannot_start_is_one_line_before_the_rollout(capsys, monkeypatch, run):
    import mujoco

    def no_gl(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'glGetError'")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    video = run.parent / "v.mp4"
    assert_refused(capsys, run, "eval", run, *SMALL_EVAL, "--video", video,
                   needles=("--video", "MUJOCO_GL", "without --video"))  # fmt: skip
    assert not video.exists()


def test_a_rendering_failure_keeps_the_evaluation(capsys, monkeypatch, run):
    import optimal_control.render
    import rl.evaluation.policy

    def broken(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'glGetError'")

    monkeypatch.setattr(optimal_control.render, "check_offscreen_rendering", lambda: None)
    monkeypatch.setattr(rl.evaluation.policy, "render_qpos", broken)
    with pytest.warns(UserWarning, match="no video: rendering failed .AttributeError"):
        code, err = run_cli(
            capsys, "eval", run, *SMALL_EVAL, "--video", run.parent / "v.mp4", "--video-min-s", "0"
        )
    assert code == 0, err
    result = json.loads((run / EVAL_FILE).read_text())
    assert "survival_fraction" in result and "no video" in result["video_note"]


# ------------------------------------------------------------------ the right flag, advice, litter
@pytest.mark.parametrize(
    "args",
    [["train", "--resume", "RUN"], ["eval", *SMALL_EVAL, "RUN"],
     ["eval", "--no-use-onnx", *SMALL_EVAL, "RUN"], ["eval-curve", "RUN"]],
    ids=["resume", "eval", "eval-no-onnx", "eval-curve"],
)  # fmt: skip
def test_a_run_without_its_config_says_to_restore_it(capsys, run, args):
    (run / CONFIG_FILE).unlink()
    args = [run if a == "RUN" else a for a in args]
    assert_refused(capsys, run, *args, needles=(CONFIG_FILE, "restore", "new run"))


def test_compare_of_an_unfinished_run_names_the_resume(capsys, run, tmp_path):
    (run / METRICS_FILE).unlink()
    assert_refused(capsys, run, "compare", run, "--out", tmp_path / "cmp",
                   needles=(METRICS_FILE, f"a2cf-mb train --resume {run}"))  # fmt: skip
    assert not (tmp_path / "cmp").exists()


def test_a_garbage_lock_of_an_hour_ago_is_taken_over_by_name(run):
    lock = run / LOCK_FILE
    lock.write_bytes(bytes(range(256)))
    os.utime(lock, (lock.stat().st_atime - 3600, lock.stat().st_mtime - 3600))
    with pytest.warns(StaleLockWarning, match=str(lock)), RunFolderLock(run, create=False):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
    assert not lock.exists()


@pytest.mark.parametrize("where", ["--run-name", "--out"])
def test_a_name_too_long_for_the_file_system_leaves_no_folder(capsys, tmp_path, where):
    long = "x" * 300
    args = (
        ["--out", tmp_path / "long", "--run-name", long]
        if where == "--run-name"
        else ["--out", tmp_path / "long" / long]
    )
    assert_refused(capsys, None, "train", *args, needles=(where, "300 bytes", "shorter name"))
    assert not (tmp_path / "long").exists()


def test_a_lock_that_fails_to_make_its_folder_removes_the_parents_it_made(tmp_path):
    with pytest.raises(OSError):
        RunFolderLock(tmp_path / "long" / ("x" * 300)).acquire()
    assert not (tmp_path / "long").exists()


def test_fields_of_a_saved_config_keep_their_meaning():
    """The bounds never refuse what the tasks and today's defaults hold (a run folder made
    today resumes)."""
    from rl.tasks.registry import TASKS, get_task
    from rl.training.config import TrainConfig

    for name in TASKS:
        task = get_task(name)
        assert dataclasses.replace(task) == task
    assert TrainConfig.from_dict(TrainConfig().to_dict()) == TrainConfig()


# ------------------------------------------------------------------ kills and other users (slow)
@pytest.mark.slow
def test_sigkill_anywhere_in_the_run_then_resume_equals_the_uninterrupted_run(tmp_path):
    """Kills at seeded random moments over the whole run (warm-up, rollouts, updates, saves,
    export), not only inside the save window: the resume ends equal to the uninterrupted run."""
    import random
    import signal
    import time

    from test_train_faults import TINY, _actor, _assert_same, _train

    start = time.time()
    whole = _train(*TINY, "--out", str(tmp_path), "--run-name", "whole")
    assert whole.wait(timeout=300) == 0, whole.stderr.read()
    span_s = time.time() - start
    reference = _actor(tmp_path / "whole")
    rng = random.Random(56)
    for i in range(3):
        name = f"kill{i}"
        proc = _train(*TINY, "--out", str(tmp_path), "--run-name", name)
        time.sleep(rng.uniform(0.0, span_s))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        if (tmp_path / name / CONFIG_FILE).exists():
            resumed = _train("--resume", str(tmp_path / name))
        else:  # killed before the run began: the same command again starts it in that folder
            resumed = _train(*TINY, "--out", str(tmp_path), "--run-name", name)
        assert resumed.wait(timeout=300) == 0, resumed.stderr.read()
        _assert_same(reference, _actor(tmp_path / name))


NOBODY = 65534


def as_nobody() -> None:
    """``preexec_fn``: drop to the unprivileged user ``nobody``."""
    os.setgroups([])
    os.setgid(NOBODY)
    os.setuid(NOBODY)


def nobody_can_run_python() -> str:
    """Why an unprivileged user cannot run this interpreter here ("" when they can)."""
    if os.geteuid() != 0:
        return "needs root to become another user"
    try:
        done = subprocess.run(
            [sys.executable, "-c", "import a2cf_mb.cli"], preexec_fn=as_nobody, cwd="/",
            capture_output=True, timeout=120,
        )  # fmt: skip
    except OSError as err:
        return f"user nobody cannot start {sys.executable} ({err.strerror})"
    return "" if done.returncode == 0 else "user nobody cannot import a2cf_mb from here"


@pytest.mark.slow
def test_an_unprivileged_user_is_refused_a_run_folder_it_cannot_write(probe_run):
    why = nobody_can_run_python()
    if why:
        pytest.skip(why)
    root = Path(tempfile.mkdtemp(dir="/tmp"))
    root.chmod(0o755)
    try:
        run = Path(shutil.copytree(probe_run, root / "run"))
        before = snapshot(run)
        done = subprocess.run(
            [sys.executable, "-m", "a2cf_mb", "train", "--resume", str(run), "--iterations",
             str(ITERATIONS + 1)],
            preexec_fn=as_nobody, cwd="/", capture_output=True, text=True, timeout=300,
            env={**os.environ, DEBUG_ENV: "0", TRACEBACK_DIR_ENV: "/tmp"},
        )  # fmt: skip
        assert done.returncode == 2, done.stderr
        assert_one_line(done.stderr, "Permission denied", str(run))
        assert snapshot(run) == before
    finally:
        shutil.rmtree(root)


# ------------------------------------------------------------------ damaged run files (slow)
RUN_FILES = (
    CONFIG_FILE, "git.json", f"{CHECKPOINT_DIR}/last.pt", f"{CHECKPOINT_DIR}/model_2.pt",
    f"{CHECKPOINT_DIR}/model_4.pt", "curriculum.jsonl", METRICS_FILE, METRICS_LOG, "policy.onnx",
    "policy.json", "events", EVAL_FILE, "evals_checkpoints.jsonl", LOCK_FILE,
)  # fmt: skip
"""Every kind of file a run folder holds ("events": its TensorBoard file)."""

RUN_COMMANDS = {
    "resume": ["train", "--resume", "RUN"],
    "eval": ["eval", *SMALL_EVAL, "RUN"],
    "eval-checkpoint": ["eval", "--no-use-onnx", *SMALL_EVAL, "RUN"],
    "eval-curve": ["eval-curve", "--num-envs", "2", "RUN"],
    "compare": ["compare", "RUN", "--out", "OUT"],
}
DAMAGE = {
    "half": lambda data: data[: len(data) // 2],
    "empty": lambda data: b"",
    "random": lambda data: bytes(range(256)) * 8,
    "deleted": None,
}


def damage_file(run: Path, name: str, how: str) -> None:
    """Damage (or delete) one file of ``run``; files a finished run may lack are made first."""
    path = next(run.glob("events.out.tfevents*")) if name == "events" else run / name
    if not path.exists():  # eval.json, eval-curve's rows and the lock come with use
        path.write_text(json.dumps({"iteration": 2, "seed": 1}) + "\n")
    if DAMAGE[how] is None:
        path.unlink()
    else:
        path.write_bytes(DAMAGE[how](path.read_bytes()))


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(RUN_COMMANDS))
@pytest.mark.parametrize("how", sorted(DAMAGE))
@pytest.mark.parametrize("name", RUN_FILES)
def test_a_damaged_run_file_is_read_or_refused_in_one_line(
    capsys, run, tmp_path, name, how, command
):
    """Whatever file is damaged, each command either works (a warning at most) or refuses in one
    line with exit 2 and the folder unchanged; never a traceback or an unexpected error."""
    damage_file(run, name, how)
    before = snapshot(run)
    out = tmp_path / "compare"
    args = [str(out) if a == "OUT" else run if a == "RUN" else a for a in RUN_COMMANDS[command]]
    code, err = run_cli(capsys, *args)
    assert code in (0, 2), err
    assert "Traceback" not in err and "unexpected error" not in err, err
    if code == 2:
        assert_one_line(err)
        assert snapshot(run) == before


# ------------------------------------------------------------------ lock files
def lock_text(kind: str) -> bytes:
    """The bytes of a ``run.lock`` of one kind."""
    import socket

    holder = {"host": socket.gethostname(), "started_utc": "2026-01-01T00:00:00Z",
              "command": "a2cf-mb train", "process": None}  # fmt: skip
    if kind == "empty":
        return b""
    if kind == "junk":
        return bytes(range(256))
    if kind == "list":
        return b"[1, 2]"
    if kind == "dead pid":
        child = subprocess.Popen([sys.executable, "-c", "pass"])
        child.wait()
        return json.dumps({**holder, "pid": child.pid}).encode()
    if kind == "reused pid":  # a live pid whose start time is not the recorded one
        return json.dumps({**holder, "pid": os.getppid(), "process": "boot:0"}).encode()
    if kind == "live pid":
        return json.dumps({**holder, "pid": os.getppid()}).encode()
    if kind == "other host":
        return json.dumps({**holder, "pid": 1, "host": "elsewhere"}).encode()
    raise ValueError(kind)


# (kind, age [s], taken over): a lock whose holder is gone is taken over with a warning naming
# it; a live holder's, another host's or one being written right now refuses in one line
LOCK_CASES = [
    ("empty", 0, False), ("empty", 3600, True), ("junk", 0, False), ("junk", 3600, True),
    ("list", 3600, True), ("dead pid", 0, True), ("reused pid", 0, True), ("live pid", 3600, False),
    ("other host", 3600, False),
]  # fmt: skip


@pytest.mark.parametrize(("kind", "age_s", "taken"), LOCK_CASES)
def test_a_lock_file_is_taken_over_or_refused_by_what_it_says(tmp_path, kind, age_s, taken):
    from rl.runs.folder import RunFolderBusyError

    lock = tmp_path / LOCK_FILE
    lock.write_bytes(lock_text(kind))
    old = lock.stat().st_mtime - age_s
    os.utime(lock, (old, old))
    if taken:
        with pytest.warns(StaleLockWarning, match=str(lock)), RunFolderLock(tmp_path, False):
            assert json.loads(lock.read_text())["pid"] == os.getpid()
        assert not lock.exists()
    else:
        before = lock.read_bytes()
        with pytest.raises(RunFolderBusyError, match="is being written by") as err:
            RunFolderLock(tmp_path, create=False).acquire()
        assert str(lock) in str(err.value) and "\n" not in str(err.value)
        assert lock.read_bytes() == before


def test_a_rendering_failure_keeps_the_oracle_artifact(capsys, monkeypatch, tmp_path):
    """solve-walk / solve-dance render after the whole solve: a GL failure there is a note in
    the artifact, never a lost solve."""
    import optimal_control.render

    def broken(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'glGetError'")

    monkeypatch.setattr(optimal_control.render, "render_reference", broken)
    out = tmp_path / "walk"
    code, err = run_cli(
        capsys, "solve-walk", "--duration", "2", "--alphas", "1.0", "--novice-alpha", "1.0",
        "--no-progress", "--out", out,
    )  # fmt: skip
    assert code == 0, err
    notes = [p.read_text() for p in out.glob("*.json")]
    assert any("no video: rendering failed (AttributeError" in text for text in notes)


@pytest.mark.parametrize(
    ("edit", "needles"),
    [("degrees", ("look like degrees", "convert them to radians")),
     ("nan", ("NaN/inf at frame 5", "--clip-frames A:B"))],
)  # fmt: skip
def test_a_clip_in_degrees_or_with_nan_says_what_to_do(capsys, tmp_path, edit, needles):
    import numpy as np

    rows = np.zeros((40, 36))
    rows[:, 2], rows[:, 6] = 0.75, 1.0  # standing height, identity quaternion (xyzw)
    rows[:, 7 + 3] = 20.0 if edit == "degrees" else 0.3  # a knee, in degrees or radians
    if edit == "nan":
        rows[5, 10] = np.nan
    clip = tmp_path / "clip.csv"
    np.savetxt(clip, rows, delimiter=",")
    out = tmp_path / "art"
    assert_refused(capsys, None, "solve-dance", "--clip", clip, "--out", out, needles=needles)
    assert not out.exists()


# ------------------------------------------------------------------ the wrong kind of input
WRONG_INPUTS = [
    (["eval", "FILE"], "is a file, not a run folder"),
    (["eval", "EMPTY"], "is not a run folder"),
    (["eval", "RUN/checkpoints/last.pt"], "its run folder above it"),
    (["eval-curve", "FILE"], "is a file, not a run folder"),
    (["eval-curve", "RUN/policy.onnx"], "its run folder above it"),
    (["compare", "FILE", "--out", "OUT"], "is a file, not a run folder"),
    (["compare", "EMPTY", "--out", "OUT"], "is not a run folder"),
    (["train", "--resume", "FILE"], "is a file, not a run folder"),
    (["solve-dance", "--clip", "EMPTY", "--out", "OUT"], "is not a file; check --clip"),
    (["solve-dance", "--clip", "FILE", "--out", "OUT"], "use .csv or .npz"),
    (["train", "--warmstart", "FILE", "--out", "OUT"], "nor an oracle artifact folder"),
    (["train", "--task", "track", "--reference", "FILE", "--out", "OUT"], "use a .csv or .npz"),
]


@pytest.mark.parametrize(
    ("args", "needle"), WRONG_INPUTS, ids=[" ".join(a) for a, _ in WRONG_INPUTS]
)
def test_the_wrong_kind_of_input_is_one_line(capsys, probe_run, tmp_path, args, needle):
    (tmp_path / "a_file.txt").write_text("hello")
    (tmp_path / "empty").mkdir()
    names = {"FILE": tmp_path / "a_file.txt", "EMPTY": tmp_path / "empty", "OUT": tmp_path / "out"}
    args = [str(names[a]) if a in names else a.replace("RUN", str(probe_run)) for a in args]
    before = snapshot(probe_run)
    assert_refused(capsys, None, *args, needles=(needle,))
    assert snapshot(probe_run) == before
    assert not (tmp_path / "out").exists()


def test_a_folder_left_by_a_run_killed_before_its_config_says_to_start_it_again(capsys, tmp_path):
    folder = tmp_path / "unstarted"
    folder.mkdir()
    (folder / LOCK_FILE).write_text("{}")
    assert_refused(capsys, folder, "train", "--resume", folder,
                   needles=("holds no run yet", "start it again with the same"))  # fmt: skip


def test_git_refusing_a_checkout_is_named_not_silent(monkeypatch, tmp_path):
    """A checkout git will not read (another user's: "dubious ownership") records no commit in
    git.json; git_refusal gives git's reason for train's warning. Outside any checkout: none."""
    import optimal_control.files as files

    assert files.git_refusal(tmp_path) is None  # no checkout: nothing to warn about
    said = "fatal: detected dubious ownership in repository at '/work/main'\nmore"
    refused = subprocess.CompletedProcess(["git"], 128, stdout="", stderr=said)
    monkeypatch.setattr(files.subprocess, "run", lambda *a, **k: refused)
    assert files.git_refusal(tmp_path) == "detected dubious ownership in repository at '/work/main'"


@pytest.mark.parametrize("how", ["half", "deleted"])
def test_compare_of_a_damaged_tensorboard_file_says_so(capsys, run, tmp_path, how):
    damage_file(run, "events", how)
    with pytest.warns(UserWarning, match="TensorBoard files of .* damaged or missing"):
        code, err = run_cli(capsys, "compare", run, "--out", tmp_path / "cmp")
    assert code == 0, err
