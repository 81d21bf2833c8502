"""The oracle of a clip the user brings: ``solve-dance --clip FILE --clip-frames A:B`` solves the
segment ``train --reference-frames A:B`` tracks; ``train --oracle`` solves it once into a cache
keyed by the reference's fingerprint and reuses it; its torques reach the PD law
(``--task-action-feedforward``), its eta0 works per 1 s bin in an assist mode, and the keyword
``oracle`` names it for ``--warmstart`` / ``--coach-source``. Every clip is built here."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from optimal_control.artifact import OracleArtifact
from optimal_control.reference_sources import load_reference, parse_frames, reference_fingerprint
from rl.envs.task_schema import quiet
from rl.tasks.registry import make_env, resolve_task
from rl.training.config import TrainConfig
from rl.training.oracle import CACHE_DIR, resolve_oracle
from robots import g1

FPS = 30.0


@pytest.fixture(scope="module")
def sway_csv(tmp_path_factory, g1_pin) -> str:
    """A 2.5 s, 30 fps LAFAN1-layout CSV: the stand pose bobbing and waving an arm."""
    t = np.arange(75) / FPS
    rows = np.tile(g1_pin.q_stand, (t.size, 1))
    rows[:, 7 + 15] += 0.5 * np.sin(2 * np.pi * 0.5 * t)  # left shoulder pitch
    rows[:, 2] += 0.02 * np.sin(2 * np.pi * 1.0 * t)
    path = tmp_path_factory.mktemp("clips") / "sway.csv"
    np.savetxt(path, rows, delimiter=",")
    return str(path)


def _train_cfg(csv: str, out, frames: str = "0:45", **kw) -> TrainConfig:
    return TrainConfig(
        task="track", reference=(csv,), reference_frames=frames, oracle=True, out=str(out), **kw
    )


@pytest.fixture(scope="module")
def oracle_cfg(sway_csv, tmp_path_factory) -> TrainConfig:
    """A run's config with its oracle solved (frames 0:45 of the clip, 1.5 s: two bins)."""
    return resolve_oracle(_train_cfg(sway_csv, tmp_path_factory.mktemp("runs"), mode="a2cf"))


def test_clip_frames_read_like_reference_frames(sway_csv, tmp_path, capsys) -> None:
    """``--clip-frames`` takes the segment ``--reference-frames`` takes, with its checks, each
    bad one a line naming ``--clip-frames``; before any folder is made."""
    from a2cf_mb.cli import main

    out = tmp_path / "d"
    args = ["solve-dance", "--clip", sway_csv, "--no-video", "--no-progress", "--alphas", "1.0"]
    assert main([*args, "--novice-alpha", "1.0", "--clip-frames", "15:60", "--out", str(out)]) == 0
    art = OracleArtifact.load(out)
    tracked = load_reference(sway_csv, parse_frames("15:60"))
    assert reference_fingerprint(art.reference) == reference_fingerprint(tracked)
    assert art.extra_summary["source"]["frames"] == [15, 60]
    assert art.extra_summary["source"]["fingerprint"] == reference_fingerprint(tracked)
    capsys.readouterr()
    for frames, needle in (("60:15", "START < STOP"), ("0:900", "out of range"),
                           ("0:20", "shorter than")):  # fmt: skip
        bad = tmp_path / f"bad_{frames.replace(':', '_')}"
        assert main([*args, "--clip-frames", frames, "--out", str(bad)]) == 2
        err = capsys.readouterr().err
        assert "--clip-frames" in err and needle in err and "Traceback" not in err, err
        assert len(err.strip().splitlines()) == 1 and not bad.exists()


def test_the_oracle_is_solved_once_per_segment(sway_csv, oracle_cfg, monkeypatch) -> None:
    """The first run solves into ``<out>/oracle_cache/<fingerprint>``; a second run on the segment
    reuses it (no solve); another segment is another fingerprint; the keyword ``oracle`` names the
    folder, and without ``--oracle`` it is refused."""
    import optimal_control.oracle

    folder = oracle_cfg.oracle_artifact
    ref = load_reference(sway_csv, (0, 45))
    assert folder.endswith(f"{CACHE_DIR}/{reference_fingerprint(ref)}")
    out = folder.rsplit(f"/{CACHE_DIR}/", 1)[0]

    def no_solve(*args, **kwargs):
        raise AssertionError("solved again")

    monkeypatch.setattr(optimal_control.oracle, "solve_dance", no_solve)
    again = resolve_oracle(_train_cfg(sway_csv, out, warmstart="oracle"))
    assert again.oracle_artifact == folder and again.warmstart == folder
    coach = resolve_oracle(
        _train_cfg(sway_csv, out, mode="coach", coach=dataclasses.replace(
            TrainConfig().coach, source="oracle"))
    )  # fmt: skip
    assert coach.coach.source == folder
    with pytest.raises(AssertionError, match="solved again"):
        resolve_oracle(_train_cfg(sway_csv, out, frames="0:60"))  # another fingerprint
    with pytest.raises(ValueError, match="add --oracle"):
        resolve_oracle(TrainConfig(task="track", reference=(sway_csv,), warmstart="oracle"))
    with pytest.raises(ValueError, match="one clip file"):
        resolve_oracle(TrainConfig(task="track", oracle=True, out=out))  # the built-in dance


def test_feedforward_puts_the_clips_planned_torques_into_the_pd_law(oracle_cfg) -> None:
    """With the oracle, the tracking library carries the artifact's joint torques (its QP's at
    alpha 1) and the PD targets shift by kd/kp qd_ref + tau_ref/kp."""
    cfg = dataclasses.replace(oracle_cfg, mode="baseline", warmstart="")
    task = resolve_task(cfg)
    assert task.phase_names == ("track",)  # without an assist head: one phase, as without
    env = make_env(quiet(dataclasses.replace(task, action_feedforward=True)), 2, num_threads=1)
    try:
        cmd = env.command_gen
        planned = OracleArtifact.load(cfg.oracle_artifact).profiles[1.0].tau_nm
        np.testing.assert_allclose(cmd.motion.joint_torque_nm.numpy(), planned, atol=1e-4)
        assert np.abs(planned).max() > 1.0  # the legs carry the robot: not all zero
        cmd.for_evaluation()
        env.reset_envs(torch.arange(2))
        qd, tau = cmd.reference_joint_feedforward()
        shift = env._action_base() - cmd.reference_joint_pos_rad()
        expected = qd * torch.as_tensor(g1.KD / g1.KP) + tau / torch.as_tensor(g1.KP)
        torch.testing.assert_close(shift, expected.float())
    finally:
        env.close()


def test_an_assist_mode_works_per_bin_of_the_clip(oracle_cfg) -> None:
    """In mode a2cf the clip's 1 s bins are the task's phases, eta0 comes per bin from the
    artifact, and the command logs the help and the failures per bin."""
    from rl.a2cf.warmstart import warmstart_eta0

    task = resolve_task(oracle_cfg)
    assert task.phase_names == ("t0s", "t1s")
    eta0 = warmstart_eta0(oracle_cfg, task)
    art = OracleArtifact.load(oracle_cfg.oracle_artifact)
    assert art.phase_names == task.phase_names
    torch.testing.assert_close(eta0, torch.tensor(art.eta0, dtype=torch.float32))
    env = make_env(quiet(task), 2, num_threads=1)
    try:
        phases = env.command_gen.motion.phase
        assert phases[:50].eq(0).all() and phases[50:].eq(1).all()
        env.step(torch.zeros(2, 35))
        log = env.command_gen.log()
        assert {"Oracle/failure_share/t0s", "Oracle/failure_share/t1s"} <= set(log)
    finally:
        env.close()


def test_a_run_records_the_artifact_it_used(sway_csv, oracle_cfg) -> None:
    """``train --oracle --task-action-feedforward``: config.json names the cached artifact."""
    from a2cf_mb.cli import main

    out = oracle_cfg.oracle_artifact.rsplit(f"/{CACHE_DIR}/", 1)[0]
    assert main(["train", "--task", "track", "--reference", sway_csv, "--reference-frames",
                 "0:45", "--oracle", "--task-action-feedforward", "--mode", "baseline",
                 "--env-num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1",
                 "--eval-interval", "0", "--no-export-onnx", "--out", out,
                 "--run-name", "ff"]) == 0  # fmt: skip
    saved = json.loads((Path(out) / "ff" / "config.json").read_text())
    assert saved["train"]["oracle_artifact"] == oracle_cfg.oracle_artifact
    assert saved["task"]["action_feedforward"] is True
