"""Prepare the payload of one GPU visit: what the lent machine's image lacks, split into calls.

The lent GPU machine (docs/gpu.md, "A GPU visit") has Python 3.12, CUDA torch, numpy, scipy,
onnx, onnxruntime, tensorboard and pytest, no package index, and takes at most 64 MiB of working
tree per call, the tracked files included. This script, run where PyPI is reachable, writes:

    .gpu_payload/py3.12/call1/{payload.tar.xz.01, parts.sha256, payload.id}
    .gpu_payload/py3.12/call2/{payload.tar.xz.02, parts.sha256, payload.id}
    ...
    .gpu_payload/py3.12/call<last>/backflip_oracle/   (the backflip stage's reference)

One folder per device call, each small enough to travel beside the working tree (``carry``).
The tarball holds the wheels of :data:`PAYLOAD_PACKAGES` (re-zipped without compression, so xz
compresses their contents) and the G1 files the MuJoCo model loads (the URDF and the meshes it
names: 15 MB of the 125 MB example-robot-data). ``run_gpu_check.sh`` stashes each call's part on
the machine and, once every part is there, unpacks and installs them with ``pip --target``.
The last call also carries a copy of the ``solve-backflip`` artifact (``--reference``, 1 MB,
outside the tarball: a new solve changes no part), the reference of the check's backflip stage;
it is solved here because the TO needs Pinocchio and CasADi, which the lent image lacks.

    .venv/bin/python docs/results/gpu/make_payload.py                    # for the GPU machine
    .venv/bin/python docs/results/gpu/make_payload.py --python-version 3.11   # the CPU dry run

Versions are those installed in the interpreter that runs this script (the project's tested
environment). A payload whose inputs did not change is not rebuilt (xz at level 9 takes minutes).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import json
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]

REFERENCE = "runs/backflip_track/oracle"
"""The backflip stage's reference, as docs/results/backflip_track/run.sh solves it."""

REFERENCE_CARRY = "backflip_oracle"
"""Its folder in the last call's folder (``run_gpu_check.sh`` looks for it there)."""

PAYLOAD_PACKAGES = (
    "mujoco",
    "mujoco-core",
    "mujoco-warp",
    "warp-lang",
    "rsl-rl-lib",
    "tensordict",
    "pyvers",
    "GitPython",
    "gitdb",
    "smmap",
)
"""What the lent image lacks and the check imports (mujoco's glfw, pyopengl and mujoco-studio are
rendering extras: ``import mujoco`` goes on without them). Never torch, numpy or scipy: a second
copy would shadow the image's CUDA build."""

LIMIT_TREE_BYTES = 64 * 2**20
"""What one device call carries at most: the working tree and the carried paths [bytes]."""

PLATFORMS = (
    "manylinux_2_28_x86_64",
    "manylinux_2_27_x86_64",
    "manylinux_2_17_x86_64",
    "manylinux2014_x86_64",
    "manylinux1_x86_64",
)
"""Wheel platforms pip may pick for the lent machine (x86-64, glibc 2.28 or newer)."""

PAYLOAD_FORMAT = 1
"""Bumped when the payload's layout changes, so an old one is rebuilt."""


def travelling_tree_bytes(repo: Path = REPO) -> int:
    """Bytes of the files a device call sends besides ``carry``: tracked and untracked files git
    does not ignore, as they are in the working tree now."""
    names = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=repo,
        check=True,
        capture_output=True,
    ).stdout.split(b"\0")
    paths = (repo / n.decode() for n in names if n)
    return sum(p.stat().st_size for p in paths if p.is_file() and not p.is_symlink())


def g1_files() -> list[Path]:
    """The G1 files the MuJoCo model loads: the 29-DoF URDF and the meshes it names."""
    from robots.assets import g1_mesh_dir, g1_urdf_path

    urdf = g1_urdf_path()
    names = sorted(set(re.findall(r'filename="[^"]*?([^/"]+)"', urdf.read_text())))
    meshes = [g1_mesh_dir() / n for n in names]
    missing = [str(m) for m in meshes if not m.is_file()]
    if missing:
        raise FileNotFoundError(f"{urdf} names meshes that are not there: {missing}")
    return [urdf, *meshes]


def download_wheels(python_version: str, dest: Path) -> list[Path]:
    """One wheel per package of :data:`PAYLOAD_PACKAGES`, at this interpreter's installed
    versions, for CPython ``python_version`` on x86-64 Linux."""
    pins = []
    for name in PAYLOAD_PACKAGES:
        try:
            pins.append(f"{name}=={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError as err:
            raise SystemExit(
                f"{name} is not installed in {sys.executable}: the payload takes the versions of "
                f'the tested environment; install the gpu extra there (pip install -e ".[gpu]").'
            ) from err
    dest.mkdir(parents=True, exist_ok=True)
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "download",
        "-q",
        "--no-deps",
        "--only-binary=:all:",
        "--python-version",
        python_version,
        "--implementation",
        "cp",
        "-d",
        str(dest),
    ]
    for platform in PLATFORMS:
        cmd += ["--platform", platform]
    subprocess.run(cmd + pins, check=True)
    wheels = []
    for pin in pins:
        name, version = pin.split("==")
        stem = re.sub(r"[-_.]+", "_", name).lower()
        found = [w for w in dest.glob("*.whl") if w.name.lower().startswith(f"{stem}-{version}-")]
        if len(found) != 1:
            raise SystemExit(f"expected one wheel of {pin} in {dest}, found {found}")
        wheels.append(found[0])
    return wheels


def stored_wheel(wheel: Path, dest: Path) -> Path:
    """``wheel`` re-zipped without compression (same entries, same RECORD) into ``dest``: xz then
    compresses the contents, not deflate's output."""
    out = dest / wheel.name
    with zipfile.ZipFile(wheel) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as dst:
        for info in src.infolist():
            data = src.read(info)
            info.compress_type = zipfile.ZIP_STORED
            dst.writestr(info, data)
    return out


def digest(paths: list[Path]) -> str:
    """sha256 over the names and contents of ``paths`` (the payload's identity)."""
    h = hashlib.sha256(f"format {PAYLOAD_FORMAT}".encode())
    for p in paths:
        h.update(p.name.encode())
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(2**20), b""):
                h.update(block)
    return h.hexdigest()


def build_tarball(wheels: list[Path], g1: list[Path], work: Path, tarball: Path) -> None:
    """``wheels/*.whl`` (stored) and ``g1_description/{urdf,meshes}/...`` in one tar.xz."""
    stored = work / "stored"
    shutil.rmtree(stored, ignore_errors=True)
    stored.mkdir(parents=True)

    def clean(info: tarfile.TarInfo) -> tarfile.TarInfo:
        info.mtime, info.uid, info.gid, info.uname, info.gname = 0, 0, 0, "", ""
        return info

    with tarfile.open(tarball, "w:xz", preset=9) as tar:
        for w in wheels:
            tar.add(stored_wheel(w, stored), f"wheels/{w.name}", filter=clean)
        for f in g1:
            tar.add(f, f"g1_description/{f.parent.name}/{f.name}", filter=clean)
    shutil.rmtree(stored)


def split(tarball: Path, part_bytes: int, out: Path, payload_id: str) -> list[Path]:
    """``out/call<i>/payload.tar.xz.<i>`` of at most ``part_bytes`` each, with the list of all
    parts' sha256 (``parts.sha256``, the format of ``sha256sum -c``) and the payload's id."""
    data = tarball.read_bytes()
    chunks = [data[i : i + part_bytes] for i in range(0, len(data), part_bytes)]
    names = [f"payload.tar.xz.{i + 1:02d}" for i in range(len(chunks))]
    sums = "".join(
        f"{hashlib.sha256(c).hexdigest()}  {n}\n" for c, n in zip(chunks, names, strict=True)
    )
    folders = []
    for i, (chunk, name) in enumerate(zip(chunks, names, strict=True), start=1):
        folder = out / f"call{i}"
        folder.mkdir(parents=True)
        (folder / name).write_bytes(chunk)
        (folder / "parts.sha256").write_text(sums)
        (folder / "payload.id").write_text(payload_id + "\n")
        folders.append(folder)
    return folders


def add_reference(plan: dict, reference: Path | None) -> dict:
    """``plan`` with a copy of the artifact ``reference`` in its last call's folder (none left
    there when ``reference`` is None), that call's ``carry_bytes`` counting it."""
    last = REPO / plan["calls"][-1]["carry"]
    shutil.rmtree(last / REFERENCE_CARRY, ignore_errors=True)
    plan["reference"] = None
    if reference is not None:
        if not (reference / "oracle.json").is_file():
            raise SystemExit(
                f"{reference} is no solve-backflip artifact (no oracle.json): solve it first, "
                f"`a2cf-mb solve-backflip --oracle-out {REFERENCE} --no-oracle-progress` (about "
                "3 min), or pass --reference '' to leave the backflip stage out"
            )
        shutil.copytree(reference, last / REFERENCE_CARRY)
        plan["reference"] = str(reference)
    plan["calls"][-1]["carry_bytes"] = sum(p.stat().st_size for p in last.rglob("*") if p.is_file())
    return plan


def make_payload(python_version: str, out_root: Path, headroom_bytes: int) -> dict:
    """Build (or reuse) the payload for CPython ``python_version`` under ``out_root``; returns
    the plan: the folder each call carries and its size beside the working tree."""
    out = out_root / f"py{python_version}"
    wheels = download_wheels(python_version, out_root / "cache" / f"wheels-py{python_version}")
    g1 = g1_files()
    payload_id = digest(wheels + g1)[:16]
    tarball = out_root / "cache" / f"payload-py{python_version}-{payload_id}.tar.xz"
    if not tarball.is_file():
        print(f"compressing {len(wheels)} wheels and {len(g1)} G1 files (xz -9: minutes)...")
        partial = tarball.with_suffix(".partial")
        build_tarball(wheels, g1, out_root / "cache", partial)
        partial.rename(tarball)
    tree = travelling_tree_bytes()
    part_bytes = LIMIT_TREE_BYTES - tree - headroom_bytes
    if part_bytes < 2**20:
        raise SystemExit(
            f"the working tree takes {tree / 2**20:.1f} MiB of a call's 64 MiB: no room for a part"
        )
    plan_file = out / "plan.json"
    if plan_file.is_file():
        plan = json.loads(plan_file.read_text())
        if plan["payload_id"] == payload_id and plan["part_bytes"] == part_bytes:
            return plan
    shutil.rmtree(out, ignore_errors=True)
    folders = split(tarball, part_bytes, out, payload_id)
    calls = [
        {
            "carry": str(f.relative_to(REPO)) if f.is_relative_to(REPO) else str(f),
            "carry_bytes": sum(p.stat().st_size for p in f.iterdir()),
        }
        for f in folders
    ]
    plan = {
        "payload_id": payload_id,
        "python_version": python_version,
        "packages": [w.name for w in wheels],
        "g1_files": len(g1),
        "g1_bytes": sum(f.stat().st_size for f in g1),
        "tarball_bytes": tarball.stat().st_size,
        "tree_bytes_at_build": tree,
        "part_bytes": part_bytes,
        "calls": calls,
    }
    plan_file.write_text(json.dumps(plan, indent=1) + "\n")
    return plan


def main() -> None:
    """Parse the flags, build the payload, print the calls to make."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python-version", default="3.12", help="CPython of the target [X.Y]")
    parser.add_argument("--out", default=str(REPO / ".gpu_payload"), help="ignored folder")
    parser.add_argument(
        "--reference",
        default=str(REPO / REFERENCE),
        help="solve-backflip artifact the last call carries for the backflip stage; '': none",
    )
    parser.add_argument(
        "--headroom-mib",
        type=float,
        default=2.0,
        help="room left in each call for the working tree to grow before the visit [MiB]",
    )
    args = parser.parse_args()
    out_root = Path(args.out).resolve()
    out_root.mkdir(parents=True, exist_ok=True)
    if out_root.is_relative_to(REPO):
        ignored = subprocess.run(["git", "check-ignore", "-q", str(out_root)], cwd=REPO)
        if ignored.returncode != 0:
            raise SystemExit(f"{out_root} is not ignored by git: wheels must never be committed")
    plan = make_payload(args.python_version, out_root, int(args.headroom_mib * 2**20))
    plan = add_reference(plan, Path(args.reference).resolve() if args.reference else None)
    (out_root / f"py{args.python_version}" / "plan.json").write_text(
        json.dumps(plan, indent=1) + "\n"
    )
    tree = travelling_tree_bytes()
    print(
        f"payload {plan['payload_id']}: {plan['tarball_bytes'] / 2**20:.1f} MiB in "
        f"{len(plan['calls'])} calls; working tree now {tree / 2**20:.1f} MiB"
    )
    for i, call in enumerate(plan["calls"], start=1):
        total = tree + call["carry_bytes"]
        print(
            f"  call {i}: carry {call['carry']} ({call['carry_bytes'] / 2**20:.1f} MiB, "
            f"{total / 2**20:.1f} MiB with the tree)"
        )
        if total > LIMIT_TREE_BYTES:
            raise SystemExit(
                f"call {i} would carry {total} bytes, over 64 MiB: rebuild the payload"
            )


if __name__ == "__main__":
    main()
