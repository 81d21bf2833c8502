"""Faults and bad inputs on the oracle side: nothing lost, nothing silent.

A SIGKILL while ``solve-walk --overwrite`` saves over an existing artifact leaves the old or the
new complete artifact (the saving window is widened by the ``A2CF_TEST_SAVE_DELAY_S`` hook of
:mod:`optimal_control.files`); every bad input exits with code 2 and one line on stderr that names
the input, before any long computation.
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from a2cf_mb.cli import DEBUG_ENV, is_user_error, main
from optimal_control.artifact import OracleArtifact
from optimal_control.files import (
    SAVE_DELAY_ENV,
    atomic_folder,
    atomic_save_npz,
    atomic_write_text,
    check_writable_dir,
    git_revision,
    read_npz,
)
from optimal_control.oracle import OracleConfig, solve_walk
from optimal_control.walk import WalkConfig
from robots import g1

REPO_ROOT = Path(__file__).resolve().parents[1]
OLD_VX, NEW_VX = 0.3, 0.45
WALK_FLAGS = ["--duration", "2", "--alphas", "1.0", "--novice-alpha", "1.0", "--no-video"]
WALK_FLAGS += ["--no-progress"]


@pytest.fixture(scope="module")
def old_walk(tmp_path_factory) -> Path:
    """A small walk artifact (vx = OLD_VX) to save over."""
    folder = tmp_path_factory.mktemp("old") / "walk"
    cfg = OracleConfig(alphas=(1.0,), novice_alpha=1.0, video=False, progress=False)
    solve_walk(WalkConfig(vx=OLD_VX, duration=2.0), dataclasses.replace(cfg, out=str(folder)))
    return folder


def _cli(*args: str, env: dict | None = None) -> subprocess.Popen:
    """``python -m a2cf_mb ARGS`` on this checkout."""
    full_env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), **(env or {})}
    full_env.pop(DEBUG_ENV, None)
    return subprocess.Popen(
        [sys.executable, "-m", "a2cf_mb", *args],
        cwd=REPO_ROOT,
        env=full_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _kill_while_saving(old_walk: Path, tmp_path: Path, delay_after_window_s: float) -> Path:
    """Copy the old artifact, run solve-walk --overwrite over it, SIGKILL it ``delay`` after its
    temporary folder appears (saving has begun); returns the target folder."""
    target = tmp_path / "walk"
    shutil.copytree(old_walk, target)
    proc = _cli(
        "solve-walk",
        *WALK_FLAGS,
        "--vx",
        str(NEW_VX),
        "--out",
        str(target),
        "--overwrite",
        env={SAVE_DELAY_ENV: "0.3"},
    )
    deadline = time.monotonic() + 120.0
    while not any(p.name.startswith(".walk.tmp-") for p in tmp_path.iterdir()):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "solve-walk never started saving"
        time.sleep(0.02)
    time.sleep(delay_after_window_s)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    return target


def _assert_old_or_new(target: Path) -> float:
    """The folder loads as one complete artifact; returns its commanded vx."""
    art = OracleArtifact.load(target)
    vx = art.extra_summary["walk_config"]["vx"]
    assert vx in (OLD_VX, NEW_VX)
    return vx


# With a 0.3 s pause per file the window is about 2.1 s: arrays at 0 s, plots until about 0.8 s,
# oracle.json 1.2 s, manifest 1.5 s, swap 2.1 s (the process then exits about 1.4 s later).
@pytest.mark.parametrize("delay_s", [0.05, 1.3, 2.6])
def test_sigkill_while_saving_over_an_artifact_leaves_old_or_new(old_walk, tmp_path, delay_s):
    """Killed inside the saving window (arrays, plots, summary, manifest, swap): old or new."""
    target = _kill_while_saving(old_walk, tmp_path, delay_s)
    _assert_old_or_new(target)
    # The next writer removes what the killed one left (its temporary folder).
    with atomic_folder(target, overwrite=True) as tmp:
        shutil.copytree(old_walk, tmp, dirs_exist_ok=True)
    assert [p.name for p in tmp_path.iterdir()] == ["walk"]
    assert _assert_old_or_new(target) == OLD_VX


@pytest.mark.slow
def test_sigkill_at_random_points_while_saving(old_walk, tmp_path):
    """Twelve kills at random points of the saving window: never a mixed or partial artifact."""
    rng = random.Random(9)
    seen = set()
    for k in range(12):
        case = tmp_path / f"case{k}"
        case.mkdir()
        seen.add(_assert_old_or_new(_kill_while_saving(old_walk, case, rng.uniform(0.0, 3.2))))
    assert seen == {OLD_VX, NEW_VX}  # kills landed both before and after the swap


def test_an_interrupted_folder_swap_is_repaired(tmp_path, old_walk):
    """Killed between 'old away' and 'new in' (the path without renameat2): load puts the old,
    complete folder back and the next writer removes the dead writer's temporary folder."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    target = tmp_path / "art"
    shutil.copytree(old_walk, tmp_path / f".art.old-{dead.pid}")
    (tmp_path / f".art.tmp-{dead.pid}").mkdir()  # the half-built new folder
    assert _assert_old_or_new(target) == OLD_VX
    with pytest.raises(ValueError, match="--overwrite"), atomic_folder(target, overwrite=False):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["art"]


def test_folder_swap_keeps_the_old_folder_on_error_and_refuses_without_overwrite(tmp_path):
    target = tmp_path / "art"
    with atomic_folder(target, overwrite=False) as tmp:
        atomic_write_text(tmp / "a.txt", "v1")
    with pytest.raises(ValueError, match="--overwrite"), atomic_folder(target, overwrite=False):
        pass
    with pytest.raises(RuntimeError), atomic_folder(target, overwrite=True) as tmp:
        atomic_write_text(tmp / "a.txt", "v2")
        raise RuntimeError("crash while building")
    assert (target / "a.txt").read_text() == "v1"
    with atomic_folder(target, overwrite=True) as tmp:
        atomic_write_text(tmp / "b.txt", "v2")
    assert sorted(p.name for p in target.iterdir()) == ["b.txt"]  # nothing stale
    assert sorted(p.name for p in tmp_path.iterdir()) == ["art"]


def test_atomic_files_and_guarded_npz_reads(tmp_path):
    path = atomic_save_npz(tmp_path / "x.npz", {"a": np.arange(3.0)})
    assert path.name == "x.npz" and sorted(read_npz(path, "test file")) == ["a"]
    (tmp_path / "junk.npz").write_bytes(b"junk")
    with pytest.raises(ValueError, match=r"test file '.*junk\.npz' is not an \.npz archive"):
        read_npz(tmp_path / "junk.npz", "test file")
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) - 30])
    with pytest.raises(ValueError, match="cut.npz"):
        read_npz(tmp_path / "cut.npz", "test file")
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        read_npz(tmp_path / "missing.npz", "test file")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    rev = git_revision(REPO_ROOT)
    assert set(rev) == {"commit", "dirty"}
    assert git_revision(Path("/")) == {"commit": None, "dirty": None}


def _run(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    return code, capsys.readouterr().err


def _assert_one_clear_line(err: str, *needles: str) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err


@pytest.fixture
def no_debug(monkeypatch):
    """Run the CLI as a user would (no A2CF_DEBUG)."""
    monkeypatch.delenv(DEBUG_ENV, raising=False)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["solve-walk", "--vx", "nan"], "--vx"),
        (["solve-walk", "--duration", "inf"], "--duration"),
        (["solve-walk", "--margin", "nan"], "--margin"),
        (["solve-dance", "--clip-source-fps", "inf"], "--clip-source-fps"),
        (["solve-backflip", "--turn-rad", "nan"], "--turn-rad"),
        (["solve-backflip", "--playback-settle-s", "inf"], "--playback-settle-s"),
    ],
)
def test_non_finite_flags_are_named(capsys, no_debug, tmp_path, args, needle):
    code, err = _run(
        capsys,
        *args,
        "--out" if args[0] != "solve-backflip" else "--oracle-out",
        str(tmp_path / "o"),
    )
    assert code == 2
    _assert_one_clear_line(err, needle, "finite")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["solve-walk", "--duration", "1e9"], ("--duration", "(0, 120] s", "step cycle")),
        (["solve-walk", "--duration", "0"], ("--duration", "(0, 120] s")),
        (["solve-walk", "--ik-dt-s", "1e-7"], ("--ik-dt-s", "[0.001, 0.02] s")),
        (["solve-dance", "--ik-dt-s", "0"], ("--ik-dt-s", "[0.001, 0.02] s")),
        (["solve-backflip", "--air-intervals", "100000"], ("--air-intervals", "[1, 100]")),
        (["solve-backflip", "--stand-intervals", "0"], ("--stand-intervals", "[1, 100]")),
    ],
)
def test_size_flags_are_bounded_with_the_limit_and_why(capsys, no_debug, tmp_path, args, needles):
    """A size out of bounds is one line naming the flag, the limit and the reason, before any
    work (``--duration 1e9`` was an OverflowError from inside placo)."""
    out_flag = {"solve-backflip": "--oracle-out"}.get(args[0], "--out")
    code, err = _run(capsys, *args, out_flag, str(tmp_path / "o"))
    assert code == 2
    _assert_one_clear_line(err, *needles, "give a value in")
    assert not (tmp_path / "o").exists()


def test_debug_env_keeps_the_traceback(monkeypatch):
    monkeypatch.setenv(DEBUG_ENV, "1")
    with pytest.raises(ValueError, match="--vx"):
        main(["solve-walk", "--vx", "nan"])


def test_only_user_errors_are_shortened():
    assert is_user_error(ValueError("bad flag")) and is_user_error(PermissionError(13, "x"))
    assert is_user_error(zipfile.BadZipFile()) and is_user_error(EOFError())
    assert not is_user_error(RuntimeError("a bug")) and not is_user_error(KeyError("k"))
    assert not is_user_error(TypeError("a bug"))


def test_walk_command_that_would_be_clamped_is_an_error(capsys, no_debug, tmp_path):
    code, err = _run(capsys, "solve-walk", "--vx", "10", "--out", str(tmp_path / "w"))
    assert code == 2
    _assert_one_clear_line(err, "--vx", "clamp", "0.556 m/s", "--max-step-forward-m")
    assert not (tmp_path / "w").exists()


def test_existing_output_needs_overwrite_and_is_checked_first(capsys, no_debug, old_walk, tmp_path):
    start = time.perf_counter()
    code, err = _run(capsys, "solve-walk", *WALK_FLAGS, "--out", str(old_walk))
    assert code == 2
    _assert_one_clear_line(err, str(old_walk), "--overwrite")
    code, err = _run(capsys, "solve-backflip", "--oracle-out", str(old_walk), "--no-use-cache")
    assert code == 2
    _assert_one_clear_line(err, str(old_walk), "--overwrite")
    assert time.perf_counter() - start < 10.0  # refused before planning or solving
    OracleArtifact.load(old_walk)  # untouched
    afile = tmp_path / "file"
    afile.write_text("x")
    code, err = _run(capsys, "solve-walk", "--out", str(afile))
    assert code == 2
    _assert_one_clear_line(err, str(afile), "not a folder")


def test_unwritable_output_fails_before_the_computation(capsys, no_debug, tmp_path):
    if os.geteuid() == 0:  # root writes through chmod; a sysfs folder refuses even root
        parent = Path("/sys/a2cf-mb-no-such-folder")
    else:
        parent = tmp_path / "read_only"
        parent.mkdir()
        parent.chmod(0o555)
    start = time.perf_counter()
    code, err = _run(capsys, "solve-walk", *WALK_FLAGS, "--out", str(parent / "walk"))
    assert code == 2
    _assert_one_clear_line(err, str(parent), "not writable")
    assert time.perf_counter() - start < 5.0


def _stand_rows(g1_pin, num: int = 40) -> np.ndarray:
    rows = np.tile(g1_pin.q_stand, (num, 1))
    rows[:, 7 + g1.JOINT_NAMES.index("right_elbow_joint")] += 0.3 * np.sin(np.arange(num) / 5)
    return rows


def _csv(path: Path, rows: np.ndarray) -> Path:
    np.savetxt(path, rows, delimiter=",")
    return path


@pytest.mark.parametrize(
    ("edit", "needles"),
    [
        (lambda r: r.__setitem__((20, 0), 1e12), ("frames 19 and 20", "m/s", "metres")),
        (lambda r: r.__setitem__((slice(20, None), 0), r[20:, 0] + 5.0), ("5 m", "150 m/s")),
        (lambda r: r.__setitem__((20, 2), r[20, 2] + 0.2), ("acceleration", "frame 20")),
    ],
    ids=["x=1e12", "5m-jump", "one-frame-spike"],
)
def test_implausible_clips_are_rejected(capsys, no_debug, tmp_path, g1_pin, edit, needles):
    rows = _stand_rows(g1_pin)
    edit(rows)
    clip = _csv(tmp_path / "clip.csv", rows)
    code, err = _run(capsys, "solve-dance", "--clip", str(clip), "--out", str(tmp_path / "d"))
    assert code == 2
    _assert_one_clear_line(err, "clip.csv", *needles)
    assert not (tmp_path / "d").exists()


def test_bad_npz_clips_are_named(capsys, no_debug, tmp_path, g1_pin):
    rows = _stand_rows(g1_pin)
    good = tmp_path / "good.npz"
    np.savez(good, qpos=rows, fps=30.0)
    data = good.read_bytes()
    cases = {
        "junk.npz": (b"not an archive", "not an .npz archive"),
        "cut.npz": (data[: len(data) // 2], "not an .npz archive"),
    }
    for name, (content, needle) in cases.items():
        (tmp_path / name).write_bytes(content)
        code, err = _run(capsys, "solve-dance", "--clip", str(tmp_path / name))
        assert code == 2
        _assert_one_clear_line(err, name, needle)
    np.savez(tmp_path / "fps.npz", qpos=rows, fps=np.array([30.0, 60.0]))
    code, err = _run(capsys, "solve-dance", "--clip", str(tmp_path / "fps.npz"))
    assert code == 2
    _assert_one_clear_line(err, "fps.npz", "'fps' must be one number", "(2,)")
    np.savez(tmp_path / "obj.npz", qpos=np.array([{"a": 1}], dtype=object))
    code, err = _run(capsys, "solve-dance", "--clip", str(tmp_path / "obj.npz"))
    assert code == 2
    _assert_one_clear_line(err, "obj.npz", "pickle")


def test_bad_backflip_warm_start_is_named_before_the_build(capsys, no_debug, tmp_path):
    junk = tmp_path / "warm.npz"
    junk.write_bytes(b"junk")
    other = tmp_path / "other.npz"
    np.savez(other, something=np.zeros(3))
    start = time.perf_counter()
    for path, needle in ((junk, "not an .npz archive"), (other, "not a backflip solution")):
        code, err = _run(
            capsys, "solve-backflip", "--warm-start", str(path), "--oracle-out", str(tmp_path / "b")
        )
        assert code == 2
        _assert_one_clear_line(err, "--warm-start", path.name, needle)
    assert time.perf_counter() - start < 10.0
    assert not (tmp_path / "b").exists()


def test_corrupt_backflip_cache_is_reported_and_replaced(tmp_path):
    from optimal_control.backflip.config import tiny_hop_config
    from optimal_control.backflip.pipeline import (
        BackflipOracleConfig,
        OutputConfig,
        solve_backflip,
    )
    from optimal_control.backflip.solve import cache_path, load_solution

    cfg = dataclasses.replace(tiny_hop_config(), cache_dir=str(tmp_path / "cache"))
    cached = cache_path(cfg)
    cached.parent.mkdir(parents=True)
    cached.write_bytes(b"\x00" * 100)  # e.g. a kill of an old, non-atomic writer
    oracle_cfg = BackflipOracleConfig(
        alphas=(1.0,), novice_alpha=1.0, video=False, progress=False, out=str(tmp_path / "hop")
    )
    with pytest.warns(UserWarning, match="corrupt cache file"):
        art, folder, report = solve_backflip(cfg, oracle_cfg, out_cfg=OutputConfig(playback=False))
    assert "corrupt cache file" in report["solver"]["cache_note"]
    assert not report["solver"]["warm_started"]
    load_solution(cached, "cache")  # replaced by a valid solution
    loaded = OracleArtifact.load(folder)
    assert (folder / "solution.npz").is_file() and "solution.npz" in json.loads(
        (folder / "manifest.json").read_text()
    )["files"]
    assert loaded.extra_summary["solver"]["cache_note"] == report["solver"]["cache_note"]


def test_writability_check_names_the_folder(tmp_path):
    assert check_writable_dir(tmp_path / "new" / "sub", "--out") == tmp_path / "new" / "sub"
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="is a file, not a folder"):
        check_writable_dir(tmp_path / "f", "--out")
    with pytest.raises(ValueError, match=r"--out '.*f/sub' is not writable"):
        check_writable_dir(tmp_path / "f" / "sub", "--out")


def test_default_output_folders_never_collide(tmp_path, monkeypatch):
    """Two solves in the same second get two folders (the second would else need --overwrite)."""
    from optimal_control.oracle import default_output_dir

    monkeypatch.chdir(tmp_path)
    first = default_output_dir("walk")
    first.mkdir(parents=True)
    second = default_output_dir("walk")
    assert second != first and not second.exists()


def test_every_solve_command_takes_overwrite():
    from a2cf_mb.cli import build_parser

    parser = build_parser()
    for command, dest in (
        ("solve-walk", "overwrite"),
        ("solve-dance", "overwrite"),
        ("solve-backflip", "oracle_overwrite"),
    ):
        assert getattr(parser.parse_args([command]), dest) is False
        assert getattr(parser.parse_args([command, "--overwrite"]), dest) is True


ARTIFACT_DAMAGES = {
    "truncated": lambda data: data[: len(data) // 2],
    "emptied": lambda data: b"",
    "junk": lambda data: bytes(range(256)) * 4,
}
TINY_TRAIN = ["--env-num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1"]


@pytest.mark.parametrize("how", list(ARTIFACT_DAMAGES))
@pytest.mark.parametrize("name", ["arrays.npz", "manifest.json", "oracle.json"])
@pytest.mark.parametrize("command", ["train", "coach"])
def test_a_damaged_artifact_is_one_line_for_each_reader(
    capsys, no_debug, old_walk, tmp_path, name, how, command
):
    """Each file of an artifact truncated, emptied or junk, read by ``train --warmstart`` and
    ``coach``: one line naming the file and to regenerate it; no run folder; the artifact as
    it was."""
    artifact = Path(shutil.copytree(old_walk, tmp_path / "walk"))
    path = artifact / name
    path.write_bytes(ARTIFACT_DAMAGES[how](path.read_bytes()))
    before = {p: p.read_bytes() for p in artifact.rglob("*") if p.is_file()}
    out = tmp_path / "runs"
    args = {
        "train": ["train", "--task", "walk", "--warmstart", str(artifact), "--out", str(out)],
        "coach": ["coach", str(artifact)],
    }[command]
    code, err = _run(capsys, *args, *(TINY_TRAIN if command == "train" else []))
    assert code == 2
    _assert_one_clear_line(err, name, "regenerate")
    assert not out.exists()
    assert {p: p.read_bytes() for p in artifact.rglob("*") if p.is_file()} == before
