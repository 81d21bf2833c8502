"""One process at a time writes a run folder: a second `train` (new run or `--resume`) is refused
in one line naming the holder, exit 2; a lock left by a killed process is taken over."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from test_training import tiny_config

from a2cf_mb.cli import DEBUG_ENV, main
from rl.runs.folder import (
    CONFIG_FILE,
    LOCK_FILE,
    METRICS_FILE,
    RunFolderBusyError,
    RunFolderLock,
    StaleLockWarning,
    _process_identity,
)
from rl.training.config import TrainConfig
from rl.training.runner import train

REPO_ROOT = Path(__file__).resolve().parents[1]
HOLD = """
import sys, time
from rl.runs.folder import RunFolderLock
with RunFolderLock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(600)
"""


def _holder(run: Path) -> subprocess.Popen:
    """Another process that holds the lock of ``run`` until killed."""
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run)], stdout=subprocess.PIPE, text=True, env=env
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()  # reaped: the pid belongs to no process now
    return proc.pid


def _write_lock(run: Path, pid: int, host: str | None = None, process: str | None = None) -> Path:
    run.mkdir(parents=True, exist_ok=True)
    entry = {"pid": pid, "host": host or socket.gethostname(), "command": "a2cf-mb train",
             "started_utc": "2026-01-02T03:04:05Z", "process": process}  # fmt: skip
    (run / LOCK_FILE).write_text(json.dumps(entry))
    return run / LOCK_FILE


def test_a_second_process_is_refused_in_one_line_naming_the_holder(
    tmp_path, capsys, monkeypatch
) -> None:
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    run = tmp_path / "busy"
    holder = _holder(run)
    try:
        lock_before = (run / LOCK_FILE).read_text()
        tiny = ["--num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1"]
        assert main(["train", "--out", str(tmp_path), "--run-name", "busy", *tiny]) == 2
        # --resume of the run that is still training: refused before reading or writing anything
        config = {"train": TrainConfig(run_name="busy", out=str(tmp_path)).to_dict()}
        (run / CONFIG_FILE).write_text(json.dumps(config))
        assert main(["train", "--resume", str(run)]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 2, lines
        for line in lines:
            assert line.startswith("a2cf-mb train: error: run folder") and "Traceback" not in line
            assert f"pid {holder.pid} on host {socket.gethostname()} since " in line, line
            assert "wait for that run to end" in line and str(run / LOCK_FILE) in line, line
        assert (run / LOCK_FILE).read_text() == lock_before  # the holder keeps its lock
        assert sorted(p.name for p in run.iterdir()) == [CONFIG_FILE, LOCK_FILE]
    finally:
        holder.kill()
        holder.wait()


def test_a_lock_left_by_a_killed_process_is_taken_over(tmp_path) -> None:
    cfg = tiny_config(tmp_path, "baseline", iterations=1, export_onnx=False)
    run = tmp_path / cfg.run_name
    holder = _holder(run)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert json.loads((run / LOCK_FILE).read_text())["pid"] == holder.pid  # left behind
    with pytest.warns(StaleLockWarning, match=f"left by pid {holder.pid}, which"):
        result = train(cfg, verbose=False)
    assert result.iterations_done == 1 and (run / METRICS_FILE).is_file()
    assert not (run / LOCK_FILE).exists()  # released at the end


def test_the_lock_names_its_holder_and_leaves_no_empty_folder(tmp_path) -> None:
    run = tmp_path / "out" / "run"
    with RunFolderLock(run):
        entry = json.loads((run / LOCK_FILE).read_text())
        assert entry["pid"] == os.getpid() and entry["host"] == socket.gethostname()
        assert entry["started_utc"].endswith("Z")
        with pytest.raises(RunFolderBusyError, match=f"pid {os.getpid()}"):
            RunFolderLock(run).acquire()  # the same process twice
    assert not (tmp_path / "out").exists()  # made for the run, nothing written: removed
    with RunFolderLock(run):
        (run / CONFIG_FILE).write_text("{}")
    assert sorted(p.name for p in run.iterdir()) == [CONFIG_FILE]
    with pytest.raises(FileNotFoundError, match="No such run folder"):
        RunFolderLock(tmp_path / "missing", create=False).acquire()


def test_only_locks_of_ended_processes_are_taken_over(tmp_path) -> None:
    run = tmp_path / "run"
    live = os.getppid()
    _write_lock(run, live)
    with pytest.raises(RunFolderBusyError, match=f"pid {live} on host"):
        RunFolderLock(run).acquire()
    _write_lock(run, _dead_pid(), host="another-host")  # cannot be checked from here
    with pytest.raises(RunFolderBusyError, match="on host another-host"):
        RunFolderLock(run).acquire()
    (run / LOCK_FILE).write_text("")  # a process between creating and writing its lock
    with pytest.raises(RunFolderBusyError, match="creating its lock"):
        RunFolderLock(run).acquire()
    os.utime(run / LOCK_FILE, (0, 0))  # ... or one killed there long ago
    with pytest.warns(StaleLockWarning, match="unreadable lock"), RunFolderLock(run):
        pass
    if _process_identity(os.getpid()) is not None:  # Linux: a reused pid is no holder
        _write_lock(run, live, process="another-boot:1")
        with pytest.warns(StaleLockWarning, match="belongs to another process"), RunFolderLock(run):
            assert json.loads((run / LOCK_FILE).read_text())["pid"] == os.getpid()
    assert not run.exists() or not (run / LOCK_FILE).exists()


def test_a_run_made_before_a_field_existed_resumes_with_what_it_ran_with(tmp_path) -> None:
    """Each field of FIELDS_ADDED_LATER missing from a saved config reads as the value the run
    trained with, not today's default (the flip A2CF run of Dec 5 keeps the assist actions in
    PPO's ratio after its help ends)."""
    from rl.runs.folder import FIELDS_ADDED_LATER, load_run_config
    from rl.training.config import TrainConfig

    data = TrainConfig().to_dict()
    for section, name in FIELDS_ADDED_LATER:
        del data[section][name]
    (tmp_path / "config.json").write_text(json.dumps({"train": data}))
    cfg = load_run_config(tmp_path)
    for (section, name), value in FIELDS_ADDED_LATER.items():
        assert getattr(getattr(cfg, section), name) == value
    assert cfg.ppo.assist_in_ratio == "always"


def test_a_run_of_an_older_recipe_is_refused_in_one_line_naming_its_commit(
    tmp_path, capsys, monkeypatch
) -> None:
    """A checkpoint trained on other observation terms than today's recipe of its task (stand
    read no velocity before Dec 6) is refused by `train --resume` and `eval` in one line that
    names the changed group and git.json; nothing in the folder is touched."""
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    tiny = ["--num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1"]
    assert main(["train", "--out", str(tmp_path), "--run-name", "old", *tiny]) == 0
    run = tmp_path / "old"
    saved = json.loads((run / CONFIG_FILE).read_text())
    terms = saved["task"]["observations"]["policy"]["terms"]
    saved["task"]["observations"]["policy"]["terms"] = [
        t for t in terms if t["name"] != "base_lin_vel"
    ]
    (run / CONFIG_FILE).write_text(json.dumps(saved))
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and p.name != LOCK_FILE}
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--iterations", "2"]) == 2
    assert main(["eval", str(run), "--num-envs", "2"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    for line in lines:
        assert "Traceback" not in line and "policy observation read" in line, line
        assert "'base_lin_vel']" in line and str(run / "git.json") in line, line
    after = {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and p.name != LOCK_FILE}
    assert after == before


def test_a_resume_says_what_of_the_recipe_changed_since_the_run_began(
    tmp_path, capsys, monkeypatch
) -> None:
    """A recipe change that still fits the checkpoint (a reward weight, a term added to or gone
    from the rewards) is named in one warning when the run is resumed; a run whose recipe is
    today's resumes without one."""
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    tiny = ["--num-envs", "4", "--num-steps-per-env", "8"]
    assert (
        main(["train", "--out", str(tmp_path), "--run-name", "r", *tiny, "--iterations", "1"]) == 0
    )
    run = tmp_path / "r"
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--iterations", "2"]) == 0
    assert "recipe" not in capsys.readouterr().err
    saved = json.loads((run / CONFIG_FILE).read_text())
    rewards = saved["task"]["rewards"]
    next(t for t in rewards if t["name"] == "alive")["weight"] = 7.0
    saved["task"]["rewards"] = [t for t in rewards if t["name"] != "torques"]
    (run / CONFIG_FILE).write_text(json.dumps(saved))
    assert main(["train", "--resume", str(run), "--iterations", "3"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "recipe" in line]
    assert len(warnings) == 1, warnings
    assert "rewards[alive].weight: 7.0 -> 1.0" in warnings[0], warnings[0]
    assert "rewards[torques]: added" in warnings[0], warnings[0]
