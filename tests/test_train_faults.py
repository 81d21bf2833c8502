"""SIGKILL of `a2cf-mb train` at points inside its saving: what loads afterwards is a complete
checkpoint, and the resumed run ends equal to the uninterrupted one (exact resume)."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from optimal_control.files import SAVE_DELAY_ENV

TINY = [
    "--mode", "a2cf", "--env-num-envs", "4", "--env-num-threads", "2", "--iterations", "4",
    "--num-steps-per-env", "8", "--save-interval", "2", "--ppo-num-mini-batches", "2",
    "--ppo-num-learning-epochs", "1", "--model-motion-hidden-dims", "16",
    "--model-critic-hidden-dims", "16", "--model-encoder-hidden-dims", "16",
    "--model-assist-hidden-dims", "8", "--model-latent-dim", "2", "--no-export-onnx",
]  # fmt: skip


def _train(*args: str, delay_s: float = 0.0) -> subprocess.Popen:
    env = {**os.environ, "A2CF_DEBUG": "0"}
    if delay_s:
        env[SAVE_DELAY_ENV] = str(delay_s)
    return subprocess.Popen(
        [sys.executable, "-m", "a2cf_mb", "train", *args],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def _actor(run: Path) -> dict:
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    return {"completed": state["completed_iterations"], "actor": state["actor_state_dict"]}


def _kill_then_resume(tmp_path: Path, name: str, wait_s: float) -> dict:
    run = tmp_path / name
    proc = _train(*TINY, "--out", str(tmp_path), "--run-name", name, delay_s=0.25)
    deadline = time.time() + 120
    while not (run / "checkpoints" / "last.pt").exists() and proc.poll() is None:
        assert time.time() < deadline
        time.sleep(0.05)
    time.sleep(wait_s)  # inside a later iteration's saving (each file write sleeps 0.25 s)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    if (run / "checkpoints" / "last.pt").exists():
        assert _actor(run)["completed"] >= 1  # a complete checkpoint, never a torn one
    resumed = _train("--resume", str(run))
    assert resumed.wait(timeout=300) == 0, resumed.stderr.read()
    return _actor(run)


def _uninterrupted(tmp_path: Path) -> dict:
    proc = _train(*TINY, "--out", str(tmp_path), "--run-name", "whole")
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    return _actor(tmp_path / "whole")


def _assert_same(a: dict, b: dict) -> None:
    assert a["completed"] == b["completed"] == 4
    for key, value in a["actor"].items():
        assert torch.equal(value, b["actor"][key]), key


def test_sigkill_while_saving_then_resume_equals_the_uninterrupted_run(tmp_path) -> None:
    _assert_same(_uninterrupted(tmp_path), _kill_then_resume(tmp_path, "killed", wait_s=0.9))


@pytest.mark.slow
def test_sigkill_at_random_points_then_resume(tmp_path) -> None:
    whole = _uninterrupted(tmp_path)
    rng = random.Random(7)
    for i in range(4):
        _assert_same(whole, _kill_then_resume(tmp_path, f"kill{i}", wait_s=rng.uniform(0.0, 2.5)))
