"""Faults a user can cause around a run folder: each is one line on stderr, and nothing is lost.

Every file of a tiny finished run is truncated, emptied or overwritten with junk and given to each
command that reads it; the main ``train`` flags are given 0, a negative, NaN and a huge value; a
missing device, a missing or foreign folder, a stale temp file, a first iteration that fails and
an unexpected exception are tried. Each refused case exits with code 2 (1 for a bug) after one
line with no traceback, and leaves every byte of the run folder as it was. The oracle's faults are
in ``tests/test_faults.py``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from test_training import tiny_config

from a2cf_mb.cli import DEBUG_ENV, TRACEBACK_DIR_ENV, main
from optimal_control.files import atomic_write_bytes
from rl.runs.folder import (
    CHECKPOINT_DIR,
    CHECKPOINT_EVALS_LOG,
    CONFIG_FILE,
    EVAL_FILE,
    LAST_CHECKPOINT,
    METRICS_FILE,
    POLICY_BUNDLE_FILE,
    POLICY_FILE,
)
from rl.training.runner import train

LAST = f"{CHECKPOINT_DIR}/{LAST_CHECKPOINT}"
KEPT = (f"{CHECKPOINT_DIR}/model_1.pt", f"{CHECKPOINT_DIR}/model_2.pt")
SMALL_EVAL = ("--num-envs", "2", "--num-steps", "3")


@pytest.fixture(autouse=True)
def as_a_user(monkeypatch, tmp_path):
    """Run the CLI as a user would: no A2CF_DEBUG, tracebacks saved under the test's folder."""
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    monkeypatch.setenv(TRACEBACK_DIR_ENV, str(tmp_path / "tracebacks"))


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished 2-iteration run (4 envs x 8 steps): checkpoints, ONNX, config, metrics, eval
    rows. Cases copy it; it is never changed."""
    root = tmp_path_factory.mktemp("finished")
    run = train(tiny_config(root, "a2cf", iterations=2, save_interval=1), verbose=False).run_dir
    (run / EVAL_FILE).write_text(json.dumps({"survival_fraction": 0.5}))
    (run / CHECKPOINT_EVALS_LOG).write_text(json.dumps({"iteration": 1, "seed": 1}) + "\n")
    return run


@pytest.fixture
def run(finished_run, tmp_path) -> Path:
    """A copy of the finished run this case may damage."""
    return Path(shutil.copytree(finished_run, tmp_path / "run"))


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def run_cli(capsys, *args: str) -> tuple[int, str]:
    """``a2cf-mb ARGS`` in this process: exit code and stderr."""
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err


def assert_one_line(err: str, *needles: str) -> None:
    """One non-empty line on stderr, no traceback, naming every needle."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err


DAMAGES = {
    "truncated": lambda data: data[: len(data) // 2],
    "emptied": lambda data: b"",
    "junk": lambda data: bytes(range(256)) * 4,
}


def damage(run: Path, relative: str, how: str) -> None:
    path = run / relative
    path.write_bytes(DAMAGES[how](path.read_bytes()))


# (files damaged, command, what the line names); a command's files are checked before its work.
FILE_CASES = [
    ((LAST, *KEPT), ["eval", "--no-use-onnx", *SMALL_EVAL], "no readable checkpoint"),
    ((LAST, *KEPT), ["train", "--resume"], "no readable checkpoint"),
    ((KEPT[0],), ["eval-curve", "--num-envs", "2"], "model_1.pt"),
    ((POLICY_FILE,), ["eval", *SMALL_EVAL], "a2cf-mb train --resume"),
    ((POLICY_FILE,), ["eval", "--sim2sim", *SMALL_EVAL], "a2cf-mb train --resume"),
    ((POLICY_FILE,), ["eval", "--sim2sim", "--no-use-onnx", *SMALL_EVAL], POLICY_FILE),
    ((POLICY_BUNDLE_FILE,), ["eval", "--sim2sim", *SMALL_EVAL], POLICY_BUNDLE_FILE),
    ((CONFIG_FILE,), ["eval", *SMALL_EVAL], CONFIG_FILE),
    ((CONFIG_FILE,), ["eval-curve"], CONFIG_FILE),
    ((CONFIG_FILE,), ["train", "--resume"], CONFIG_FILE),
    ((CONFIG_FILE,), ["compare"], CONFIG_FILE),
    ((METRICS_FILE,), ["compare"], METRICS_FILE),
    ((EVAL_FILE,), ["compare"], EVAL_FILE),
    ((CHECKPOINT_EVALS_LOG,), ["eval-curve"], CHECKPOINT_EVALS_LOG),
]


def command_line(command: list[str], run: Path, tmp_path: Path) -> list[str]:
    """The command with the run folder where it goes (and compare's output folder)."""
    if command[0] == "compare":
        return ["compare", str(run), "--out", str(tmp_path / "compare")]
    if command[:2] == ["train", "--resume"]:
        return ["train", "--resume", str(run), *command[2:]]
    return [*command, str(run)]


# An emptied JSON-lines file is a valid one with no rows (eval-curve evaluates everything again).
DAMAGED_FILE_CASES = [
    pytest.param(files, command, needle, how, id=f"{files[0]}-{how}-{' '.join(command)}")
    for files, command, needle in FILE_CASES
    for how in DAMAGES
    if not (files[0].endswith(".jsonl") and how == "emptied")
]


@pytest.mark.parametrize(("files", "command", "needle", "how"), DAMAGED_FILE_CASES)
def test_a_damaged_file_is_one_line_and_nothing_changes(
    capsys, run, tmp_path, files, command, needle, how
):
    for relative in files:
        damage(run, relative, how)
    before = snapshot(run)
    code, err = run_cli(capsys, *command_line(command, run, tmp_path))
    assert code == 2, err
    assert_one_line(err, needle)
    assert snapshot(run) == before
    assert not (tmp_path / "compare").exists()


WRONG_CONFIGS = {
    "no train section": ({"task": {}}, "no 'train'"),
    "a list": ([1, 2], "no 'train'"),
    "unknown field": ({"train": {"ppo": {"num_mini_batch": 2}}}, "train.ppo.num_mini_batch"),
    "a section of the wrong kind": ({"train": {"ppo": 3}}, "train.ppo must be a JSON object"),
    "a value out of bounds": (
        {"train": {"ppo": {"num_mini_batches": 0}}},
        "--ppo-num-mini-batches",
    ),
    "a value of the wrong type": ({"train": {"iterations": "many"}}, "wrong type"),
}


# compare reads the sections, not the TrainConfig: only a missing section stops it.
CONFIG_CASES = [
    pytest.param(saved, needle, command, id=f"{command}-{name}")
    for name, (saved, needle) in WRONG_CONFIGS.items()
    for command in ("train", "eval", "compare")
    if command != "compare" or "no 'train'" in needle
]


@pytest.mark.parametrize(("saved", "needle", "command"), CONFIG_CASES)
def test_a_config_of_valid_json_with_wrong_fields_names_the_file_and_fields(
    capsys, run, tmp_path, saved, needle, command
):
    original = json.loads((run / CONFIG_FILE).read_text())
    if isinstance(saved, dict) and "train" in saved:  # change one field of the real config
        for key, value in saved["train"].items():
            target = original["train"]
            if isinstance(value, dict) and isinstance(target.get(key), dict):
                target[key] = {**target[key], **value}
            else:
                target[key] = value
        saved = original
    (run / CONFIG_FILE).write_text(json.dumps(saved))
    before = snapshot(run)
    args = {"train": ["train", "--resume"], "eval": ["eval", *SMALL_EVAL]}.get(command, [command])
    code, err = run_cli(capsys, *command_line(args, run, tmp_path))
    assert code == 2, err
    assert_one_line(err, CONFIG_FILE, needle)
    assert snapshot(run) == before


# flag -> values it refuses ("nan" and non-integers are refused by the parser for int flags)
BAD_FLAGS = {
    "--iterations": ("0", "-1", "nan"),
    "--num-steps-per-env": ("0", "-3", "nan", "100000000"),
    "--save-interval": ("0", "-1", "nan"),
    "--torch-threads": ("-1", "nan"),
    "--random-mask-prob": ("1", "-0.1", "nan", "1e30"),
    "--env-num-envs": ("0", "-4", "nan", "100000000"),
    "--ppo-learning-rate": ("0", "-1e-3", "nan", "1e30"),
    "--ppo-num-learning-epochs": ("0", "-1", "nan", "1000000"),
    "--ppo-num-mini-batches": ("0", "-2", "nan", "1000000000"),
    "--ppo-clip-param": ("0", "-0.2", "nan", "1e30"),
    "--ppo-gamma": ("0", "-0.5", "nan", "1e30"),
    "--ppo-lam": ("-0.1", "nan", "1e30"),
    "--ppo-value-loss-coef": ("-1", "nan", "inf"),
    "--ppo-entropy-coef": ("-0.01", "nan", "inf"),
    "--ppo-max-grad-norm": ("0", "-1", "nan"),
    "--ppo-desired-kl": ("0", "-0.01", "nan"),
    "--ppo-init-noise-std": ("0", "-0.5", "nan"),
    "--ppo-assist-init-noise-std": ("0", "-0.3", "nan"),
    "--model-latent-dim": ("0", "-16", "nan", "1000000000"),
    "--model-vae-learning-rate": ("0", "-1e-3", "nan", "1e30"),
    "--model-vae-kl-weight": ("-1", "nan"),
    "--model-vae-learning-epochs": ("-1", "nan", "1000000"),
    "--env-decimation": ("0", "-1", "nan", "1000000"),
    "--env-num-threads": ("-1", "nan", "100000"),
    "--env-seed": ("-1", "nan", "10000000000"),
    "--env-history-length": ("0", "-5", "nan", "1000000"),
    "--env-clip-actions": ("0", "-1", "nan"),
    "--env-max-abs-qvel": ("0", "-200", "nan"),
    "--curriculum-epsilon": ("1", "-0.1", "nan", "1e30"),
    "--curriculum-delta": ("0", "-0.2", "nan", "1e30"),
    "--curriculum-negligible-force-n": ("-0.1", "nan"),
    "--curriculum-less-assist-progress": ("-0.8", "nan"),
    "--curriculum-skill-learned-progress": ("-0.6", "nan"),
    "--curriculum-alone-share": ("1", "-0.25", "nan", "1e30"),
    "--curriculum-alone-window": ("0", "-64", "nan", "1000000000"),
    "--curriculum-force-quantile": ("0", "-0.9", "nan", "1e30"),
    "--curriculum-anneal-iterations": ("-1", "nan", "10000000000"),
    "--curriculum-min-phase-samples": ("0", "-1", "nan", "1000000000"),
    "--eval-interval": ("-1", "nan"),
    "--eval-num-envs": ("0", "-32", "nan", "100000000"),
    "--eval-seed": ("-1", "nan", "10000000000"),
}
FLAG_CASES = [(flag, value) for flag, values in BAD_FLAGS.items() for value in values]


@pytest.mark.parametrize(("flag", "value"), FLAG_CASES)
def test_a_bad_train_flag_is_one_line_before_any_folder(capsys, tmp_path, flag, value):
    out = tmp_path / "out"
    code, err = run_cli(capsys, "train", "--out", out, "--run-name", "r", f"{flag}={value}")
    assert code == 2, err
    if (flag, value) == ("--num-steps-per-env", "100000000"):
        assert_one_line(err, "transitions")
    else:
        assert_one_line(err, flag)
    assert not out.exists()


# dotted key of policy.json -> removed; each is named in the line (sim2sim reads them all)
BUNDLE_KEYS = ("onnx", "clip_actions", "control.policy_rate_hz", "observation.terms", "joints")


@pytest.mark.parametrize("key", [*BUNDLE_KEYS, "joints[0].kp", "observation.terms[1].columns"])
def test_a_bundle_of_valid_json_without_a_key_names_the_file_and_key(capsys, run, key):
    bundle = json.loads((run / POLICY_BUNDLE_FILE).read_text())
    *parents, last = key.replace("[", ".").replace("]", "").split(".")
    node = bundle
    for part in parents:  # "joints[0].kp": bundle["joints"][0], then del ["kp"]
        node = node[int(part)] if part.isdigit() else node[part]
    del node[last]
    (run / POLICY_BUNDLE_FILE).write_text(json.dumps(bundle))
    before = snapshot(run)
    code, err = run_cli(capsys, "eval", "--sim2sim", *SMALL_EVAL, run)
    assert code == 2, err
    assert_one_line(err, POLICY_BUNDLE_FILE, f"'{key}'")
    assert snapshot(run) == before


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--device", "cuda:99"], "--device cuda:99"),
        (["--device", "tpu"], "--device must be cpu, cuda or cuda:N"),
        (["--env-backend", "warp", "--env-device", "cuda:99"], "--env-device cuda:99"),
    ],
)
def test_a_device_that_is_not_there_is_one_line(capsys, tmp_path, flags, needle):
    out = tmp_path / "out"
    code, err = run_cli(capsys, "train", "--out", out, "--run-name", "r", *flags)
    assert code == 2, err
    assert_one_line(err, needle)
    assert not out.exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_on_a_cpu_only_torch_says_what_to_do(capsys, tmp_path):
    out = tmp_path / "out"
    code, err = run_cli(capsys, "train", "--out", out, "--run-name", "r", "--device", "cuda")
    assert code == 2
    assert_one_line(err, "--device cuda", "without CUDA", "--device cpu")
    assert not out.exists()


def test_resume_of_a_folder_that_is_no_run_says_so_before_any_warning(capsys, tmp_path):
    missing = tmp_path / "missing"
    code, err = run_cli(capsys, "train", "--resume", missing, "--ppo-lam", "0.9")
    assert code == 2
    assert_one_line(err, "not a run folder")
    (tmp_path / "empty").mkdir()
    code, err = run_cli(capsys, "train", "--resume", tmp_path / "empty", "--ppo-lam", "0.9")
    assert code == 2
    assert_one_line(err, "not a run folder")
    assert list((tmp_path / "empty").iterdir()) == []


def test_eval_of_a_run_without_a_checkpoint_or_onnx_says_what_it_is(capsys, run):
    (run / POLICY_FILE).unlink()
    before = snapshot(run)
    code, err = run_cli(capsys, "eval", *SMALL_EVAL, run)
    assert code == 2
    assert_one_line(err, "not found", f"a2cf-mb train --resume {run}", "--no-use-onnx")
    assert snapshot(run) == before
    shutil.rmtree(run / CHECKPOINT_DIR)
    before = snapshot(run)
    # a run that logged iterations: its checkpoints are needed back (a resume would restart it)
    for args in (["eval", *SMALL_EVAL], ["eval", "--no-use-onnx", *SMALL_EVAL]):
        code, err = run_cli(capsys, *args, run)
        assert code == 2
        assert_one_line(err, "has no checkpoint", "logged 2 completed iterations", "restore")
        assert "--resume" not in err
    assert snapshot(run) == before
    # a run killed during its first iteration logged none: a resume starts it again
    for name in ("metrics.jsonl", METRICS_FILE):
        (run / name).unlink()
    before = snapshot(run)
    for args in (["eval", *SMALL_EVAL], ["eval", "--no-use-onnx", *SMALL_EVAL]):
        code, err = run_cli(capsys, *args, run)
        assert code == 2
        assert_one_line(err, "has no checkpoint", "first iteration", "--resume")
    assert snapshot(run) == before


def dead_pid() -> int:
    """The pid of a process that has ended."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_resume_removes_dead_writers_temp_files_and_exports_again(capsys, run):
    """A SIGKILL during a save leaves ``.last.pt.tmp-<pid>``: the next resume removes it (a live
    writer's is kept); a finished run's resume only exports, which repairs a damaged ONNX file."""
    pid = dead_pid()
    stale = [
        run / CHECKPOINT_DIR / f".{LAST_CHECKPOINT}.tmp-{pid}",
        run / f".{EVAL_FILE}.tmp-{pid}",
    ]
    live = run / f".{METRICS_FILE}.tmp-{os.getppid()}"  # a live process (not this one: it writes)
    for path in [*stale, live]:
        path.write_bytes(b"partial")
    damage(run, POLICY_FILE, "truncated")
    checkpoints = {p.name: p.read_bytes() for p in (run / CHECKPOINT_DIR).glob("*.pt")}
    code, err = run_cli(capsys, "train", "--resume", run)
    assert code == 0, err
    assert not any(p.exists() for p in stale) and live.exists()
    assert {p.name: p.read_bytes() for p in (run / CHECKPOINT_DIR).glob("*.pt")} == checkpoints
    from rl.agents.export import OnnxMotionPolicy

    OnnxMotionPolicy(run / POLICY_FILE)  # readable again


def test_eval_falls_back_to_the_newest_readable_checkpoint(capsys, run):
    damage(run, LAST, "truncated")
    code, err = run_cli(capsys, "eval", "--no-use-onnx", *SMALL_EVAL, run)
    assert code == 0, err
    assert_one_line(err, "warning", "model_2.pt", "newest readable")
    assert json.loads((run / EVAL_FILE).read_text())["checkpoint"] == "model_2.pt"


@pytest.mark.parametrize(
    ("error", "code", "needle"),
    [
        (ValueError("injected: bad"), 2, "injected: bad"),
        (RuntimeError("injected"), 1, "unexpected"),
    ],
)
def test_a_failed_first_iteration_leaves_no_half_made_folder(
    capsys, monkeypatch, tmp_path, error, code, needle
):
    from rl.training.runner import A2CFRunner

    def fail(self, *args, **kwargs):
        raise error

    monkeypatch.setattr(A2CFRunner, "learn", fail)
    out = tmp_path / "out"
    flags = ["--env-num-envs", "4", "--num-steps-per-env", "8", "--iterations", "1"]
    got, err = run_cli(capsys, "train", "--out", out, "--run-name", "r", *flags)
    assert got == code
    assert_one_line(err, needle)
    assert not out.exists()
    if code == 1:  # a bug: its traceback is saved, and the line says where
        (saved,) = (tmp_path / "tracebacks").iterdir()
        assert str(saved) in err and "Traceback" in saved.read_text()


def test_an_unexpected_error_is_one_line_and_debug_shows_it(capsys, monkeypatch, tmp_path):
    import a2cf_mb.commands.list_tasks as list_tasks

    def bug(args):
        raise KeyError("a bug")

    monkeypatch.setattr(list_tasks, "run", bug)
    code, err = run_cli(capsys, "list-tasks")
    assert code == 1
    assert_one_line(err, "a2cf-mb list-tasks: unexpected error: KeyError", "full traceback is in")
    with pytest.raises(KeyError):
        main(["--debug", "list-tasks"])


def test_an_atomic_write_names_the_users_file_not_its_temp_name(tmp_path):
    (tmp_path / "a_file").write_text("")
    target = tmp_path / "a_file" / EVAL_FILE
    with pytest.raises(NotADirectoryError) as err:
        atomic_write_bytes(target, b"{}")
    assert err.value.filename == str(target) and ".tmp-" not in str(err.value)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores permission bits")
def test_eval_in_a_read_only_run_folder_names_the_folder(capsys, run):
    before = snapshot(run)
    run.chmod(0o555)
    try:
        code, err = run_cli(capsys, "eval", *SMALL_EVAL, run)
    finally:
        run.chmod(0o755)
    assert code == 2
    assert_one_line(err, str(run / EVAL_FILE))
    assert ".tmp-" not in err
    assert snapshot(run) == before


@pytest.mark.parametrize("name", ["curriculum.jsonl", "evals.jsonl", METRICS_FILE])
def test_resume_rewrites_the_logs_it_owns_from_the_checkpoint(capsys, run, finished_run, name):
    """The curriculum log, the alone evaluations and metrics.json are rewritten by a resume (from
    the checkpoint and the logger's rows): junk in them is repaired, checkpoints are untouched."""
    damage(run, name, "junk")
    checkpoints = {p.name: p.read_bytes() for p in (run / CHECKPOINT_DIR).glob("*.pt")}
    code, err = run_cli(capsys, "train", "--resume", run)
    assert code == 0, err
    assert {p.name: p.read_bytes() for p in (run / CHECKPOINT_DIR).glob("*.pt")} == checkpoints
    if name == METRICS_FILE:
        rows = [json.loads((r / name).read_text())["iterations"] for r in (run, finished_run)]
        assert rows[0] == rows[1]
    else:
        assert (run / name).read_bytes() == (finished_run / name).read_bytes()


def test_warp_without_the_gpu_extra_names_the_extra(capsys, tmp_path):
    try:
        import mujoco_warp  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("the gpu extra is installed")
    out = tmp_path / "out"
    code, err = run_cli(capsys, "train", "--out", out, "--run-name", "r", "--env-backend", "warp")
    assert code == 2
    assert_one_line(err, "pip install 'a2cf-mb[gpu]'")
    assert not out.exists()
