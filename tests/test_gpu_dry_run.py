"""The GPU visit's sequence (docs/gpu.md, "A GPU visit"), dry-run on this CPU (issue 35).

A bare virtual environment stands for the lent image: only packages the image holds (the list
read on such a machine), installed from this machine's index. The payload is built for this
Python (``make_payload.py --python-version``), and every device call is replayed: a fresh copy
of the working tree with that call's carried part, ``$OUT`` empty, and the same command
(``bash docs/results/gpu/run_gpu_check.sh``) with ``DEVICE=cpu`` and tiny sizes. It asserts the
limits of the device tool: at most 64 MiB travel per call; at most 8 files come back, no deeper
than 2 folders, named in letters, digits, '.', '_' and '-', 16 MiB each.

Slow (builds a virtual environment and the payload, compiles Warp's CPU kernels): run with
``pytest -m slow tests/test_gpu_dry_run.py``. Skipped when PyPI is unreachable.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import time
import urllib.request
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
GPU = REPO / "docs" / "results" / "gpu"
_spec = importlib.util.spec_from_file_location("make_payload", GPU / "make_payload.py")
make_payload = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_payload)
LIMIT_TREE_BYTES, PAYLOAD_PACKAGES = make_payload.LIMIT_TREE_BYTES, make_payload.PAYLOAD_PACKAGES

IMAGE_ALL = frozenset(
    """
    absl-py accelerate aiofiles aiohappyeyeballs aiohttp aiosignal annotated-doc anyio attrs
    botorch build certifi charset-normalizer chex click cloudpickle cmake colorama contourpy
    coverage cuda-bindings cuda-core cuda-pathfinder cuda-toolkit cupy-cuda13x cycler cython
    diffrax e3nn einops equinox etils execnet filelock flatbuffers flax fonttools formulaic
    frozenlist fsspec gpytorch grpcio h11 h5py hf-xet httpcore httpx huggingface-hub humanize
    hypothesis idna imageio iniconfig interface-meta jax jax-cuda13-pjrt jax-cuda13-plugin
    jaxlib jaxtyping jinja2 joblib kiwisolver lazy-loader lightning lightning-utilities
    linear-operator lineax llvmlite lxml markdown markdown-it-py markupsafe matplotlib mdurl
    meson ml-dtypes mpi4py mpmath msgpack multidict multipledispatch mypy-extensions nanobind
    narwhals networkx ninja numba numba-cuda numpy numpyro nvidia-cublas nvidia-cuda-cupti
    nvidia-cuda-nvrtc nvidia-cuda-runtime nvidia-cudnn-cu13 nvidia-cufft nvidia-cufile
    nvidia-curand nvidia-cusolver nvidia-cusparse nvidia-cusparselt-cu13 nvidia-ml-py
    nvidia-nccl-cu13 nvidia-nvjitlink nvidia-nvshmem-cu13 nvidia-nvtx onnx onnx-ir onnxruntime
    onnxscript opencv-python-headless optax opt-einsum opt-einsum-fx optimistix
    orbax-checkpoint packaging pandas pathspec patsy peft pillow pip pluggy portalocker
    prometheus-client propcache protobuf psutil pyarrow pybind11 py-cpuinfo pygments pyparsing
    pyproject-hooks pyre-extensions pytest pytest-benchmark pytest-cov pytest-mock
    pytest-timeout pytest-xdist python-dateutil pytorch-lightning pyyaml regex requests rich
    sacrebleu safetensors scikit-build-core scikit-image scikit-learn scipy seaborn
    sentencepiece sentence-transformers setuptools shellingham simplejson six sortedcontainers
    statsmodels sympy tabulate tensorboard tensorboard-data-server tensorstore threadpoolctl
    tifffile tiktoken timm tokenizers toolz torch torchaudio torchdiffeq torch-geometric
    torchmetrics torchvision tqdm transformers treescope triton typer typing-extensions
    typing-inspect urllib3 uvloop wadler-lindig werkzeug wheel wrapt xarray xxhash yarl zipp
    """.split()  # noqa: SIM905 (one name per word, as read)
)
"""Every package of the lent image ('cuda'), as read on such a machine on 2026-11-17
(.library/device/KINDS.md)."""

IMAGE_INSTALL = ("torch==2.13.0", "numpy", "scipy", "onnx", "onnxruntime", "onnxscript",
                 "tensorboard", "pytest", "absl-py", "etils", "cloudpickle", "matplotlib",
                 "imageio", "tqdm")  # fmt: skip
"""What the dry run installs (with dependencies) into the bare environment: packages of the
image the check imports. torch is the CPU build of the project's README."""

INSTALL_ONLY = frozenset({"pip", "setuptools", "tzdata"})
"""Installed in the stand-in but not on the image's list: the venv's own tools, and tzdata, which
the newest python-dateutil (matplotlib's) brings; nothing the check runs imports it."""

TINY = {
    "DEVICE": "cpu",
    "COMPILE_ENVS": "2",
    "WARP_SIZES": "4 8",
    "WARP_STEPS": "3",
    "WARP_ITERATIONS": "1",
    "PARITY_ENVS": "2",
    "PARITY_STEPS": "3",
    "TRAIN_ENVS": "4",
    "TRAIN_ITERATIONS": "2",
    "MUJOCO_ENVS": "8",
    "MUJOCO_STEPS": "3",
    "MUJOCO_THREADS": "1",
    "LIMIT_COMPILE_S": "1200",  # Warp's CPU device compiles with LLVM: minutes on 2 cores
    "LIMIT_WARP_S": "600",
    "LIMIT_PARITY_S": "300",
    "LIMIT_TRAIN_S": "300",
    "LIMIT_MUJOCO_S": "120",
    "BACKFLIP_ENVS": "4",
    "BACKFLIP_ITERATIONS": "2",
    "BACKFLIP_EVAL_INTERVAL": "1",
    "BACKFLIP_EVAL_ENVS": "4",
    "LIMIT_BACKFLIP_S": "1200",
}
"""Sizes and limits of the dry run (the GPU run's defaults are in run_gpu_check.sh)."""

MAX_OUT_FILES = 8
MAX_OUT_FILE_BYTES = 16 * 2**20
OUT_NAME = re.compile(r"[A-Za-z0-9._-]+")


def pypi_reachable() -> bool:
    """Whether PyPI answers within 10 s."""
    try:
        urllib.request.urlopen("https://pypi.org/simple/pip/", timeout=10).close()
    except OSError:
        return False
    return True


def normalise(name: str) -> str:
    """A distribution name as the package index spells it (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def image_venv(path: Path) -> Path:
    """A bare virtual environment holding only packages of the lent image; its python3."""
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True)
    python = path / "bin" / "python3"
    subprocess.run([python, "-m", "pip", "install", "-q", *IMAGE_INSTALL], check=True)
    listed = subprocess.run([python, "-m", "pip", "list", "--format=json"], check=True,
                            capture_output=True, text=True).stdout  # fmt: skip
    names = {normalise(p["name"]) for p in json.loads(listed)}
    image = {normalise(n) for n in IMAGE_ALL}
    extra = names - image - INSTALL_ONLY
    assert not extra, f"the stand-in environment holds packages the image lacks: {sorted(extra)}"
    lacking = {normalise(p) for p in PAYLOAD_PACKAGES} & names
    assert not lacking, f"the stand-in environment already holds payload packages: {lacking}"
    return python


def copy_tree(dest: Path, carry: str) -> int:
    """What a device call sends: the working tree's tracked and untracked-not-ignored files and
    the carried folder, copied to ``dest``; returns the bytes."""
    names = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                           cwd=REPO, check=True, capture_output=True).stdout.split(b"\0")  # fmt: skip
    paths = [n.decode() for n in names if n]
    carried = REPO / carry
    paths += [str(p.relative_to(REPO)) for p in carried.rglob("*") if p.is_file()]
    total = 0
    for rel in paths:
        src = REPO / rel
        if not src.is_file() or src.is_symlink():
            continue
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, target)
        total += src.stat().st_size
    return total


def returned_files(out: Path) -> list[Path]:
    """The files under ``out``, checked against what the device tool brings back."""
    files = [p for p in out.rglob("*") if p.is_file()]
    assert len(files) <= MAX_OUT_FILES, f"{len(files)} files in $OUT: {files}"
    for f in files:
        rel = f.relative_to(out)
        assert len(rel.parts) <= 3, f"{rel} is deeper than 2 folders"
        assert all(OUT_NAME.fullmatch(part) for part in rel.parts), f"{rel}: name not returned"
        assert f.stat().st_size <= MAX_OUT_FILE_BYTES, f"{rel} is over 16 MiB"
    return files


def test_gpu_visit_dry_run(tmp_path: Path) -> None:
    """Every call of a visit, in order, from a bare stand-in of the image: the payload arrives in
    parts, the last call installs it and runs every stage to its end on the CPU."""
    if not pypi_reachable():
        pytest.skip("PyPI is unreachable: the payload's wheels cannot be downloaded")
    start = time.perf_counter()
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    reference = REPO / make_payload.REFERENCE
    if not (reference / "oracle.json").is_file():  # the backflip stage's reference: about 3 min
        subprocess.run([sys.executable, "-m", "a2cf_mb", "solve-backflip", "--oracle-out",
                        str(reference), "--no-oracle-progress"], check=True, cwd=REPO)  # fmt: skip
    subprocess.run([sys.executable, str(GPU / "make_payload.py"), "--python-version", version],
                   check=True, cwd=REPO)  # fmt: skip
    plan = json.loads((REPO / ".gpu_payload" / f"py{version}" / "plan.json").read_text())
    python = image_venv(tmp_path / "image")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PIP_", "PYTHON"))}
    env.update(TINY)
    env.update(
        PATH=f"{python.parent}:/usr/bin:/bin",
        PIP_CONFIG_FILE="/dev/null",  # the machine has no index and no pip configuration
        A2CF_PAYLOAD_DIR=str(tmp_path / "store"),
        WARP_CACHE_PATH=str(REPO / ".gpu_payload" / "warp_cache_dry_run"),  # kept between runs
    )
    env.pop("A2CF_G1_DESCRIPTION_DIR", None)
    calls = plan["calls"]
    for i, call in enumerate(calls, start=1):
        repo, out = tmp_path / f"call{i}" / "repo", tmp_path / f"call{i}" / "out"
        sent = copy_tree(repo, call["carry"])
        assert sent <= LIMIT_TREE_BYTES, f"call {i} sends {sent / 2**20:.1f} MiB, over 64 MiB"
        for earlier in calls[: i - 1]:  # a warm machine may keep earlier calls' ignored folders
            shutil.copytree(REPO / earlier["carry"], repo / earlier["carry"])
            os.utime(repo / earlier["carry"], (0, 0))
        out.mkdir()
        run = subprocess.run(["bash", "docs/results/gpu/run_gpu_check.sh"], cwd=repo,
                             env={**env, "OUT": str(out)}, capture_output=True, text=True)  # fmt: skip
        print(f"call {i}: {sent / 2**20:.1f} MiB sent, exit {run.returncode}")
        print(run.stdout[-3000:], run.stderr[-3000:])
        assert run.returncode == 0, (out / "summary.txt").read_text()
        files = returned_files(out)
        summary = (out / "summary.txt").read_text()
        if i < len(calls):
            assert "waiting for" in summary
            continue
        names = {f.name for f in files}
        logs = {"checks.log", "backflip.log", "backflip_run.tar"}
        assert {"summary.txt", "results.jsonl"} | logs <= names, names
        rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
        stages = {(r["stage"], r.get("what", "")) for r in rows}
        for stage in ("compile", "parity", "train", "mujoco"):
            assert (stage, "") in stages, f"no {stage} rows: {summary}"
        assert {("warp", "env"), ("warp", "end_to_end")} <= stages
        assert any(r["stage"] == "parity" and "max" in r for r in rows)
        trained = [r for r in rows if r["stage"] == "train" and "iteration" in r]
        assert len(trained) == int(TINY["TRAIN_ITERATIONS"])
        # the backflip by tracking the carried artifact, in the image's packages (no Pinocchio)
        flips = [r for r in rows if r["stage"] == "backflip" and "iteration" in r]
        assert len(flips) == int(TINY["BACKFLIP_ITERATIONS"]), summary
        evals = [r for r in rows if r["stage"] == "backflip_eval"]
        assert evals and all("flips_landed" in r for r in evals), evals
        with tarfile.open(out / "backflip_run.tar") as tar:
            packed = {m.name.partition("/")[2] for m in tar.getmembers()}
        assert {"config.json", "evals.jsonl", "metrics.jsonl", "checkpoints/last.pt"} <= packed
        assert not any(n.startswith("checkpoints/model_") for n in packed), packed
        assert "done: exit 0" in summary
        # the image's torch, never one from the payload
        assert not (tmp_path / "store" / "site" / "torch").exists()
        assert f"torch from {python.parent.parent}" in summary
    print(f"dry run of {len(calls)} calls: {time.perf_counter() - start:.0f} s")
