"""Locate the Unitree G1 description shipped by the ``example-robot-data`` package.

``example-robot-data`` 6.x installs no Python module, only files under the cmeel prefix in
site-packages. This module finds them and fails with an actionable message when they are missing.
"""

from __future__ import annotations

import os
import site
import sys
import sysconfig
from pathlib import Path

G1_URDF_NAME = "g1_29dof_rev_1_0.urdf"
"""The 29-DoF G1 (revision 1.0) URDF file name inside example-robot-data."""

_RELATIVE_DESCRIPTION_DIR = Path("cmeel.prefix/share/example-robot-data/robots/g1_description")
_ENV_OVERRIDE = "A2CF_G1_DESCRIPTION_DIR"


class RobotAssetError(FileNotFoundError):
    """The robot description (URDF or meshes) could not be found."""


def _candidate_roots() -> list[Path]:
    roots: list[str] = []
    for key in ("purelib", "platlib"):
        roots.append(sysconfig.get_paths()[key])
    roots.extend(site.getsitepackages() if hasattr(site, "getsitepackages") else [])
    roots.append(site.getusersitepackages())
    roots.extend(p for p in sys.path if p.endswith("site-packages"))
    seen: list[Path] = []
    for r in roots:
        p = Path(r)
        if p not in seen:
            seen.append(p)
    return seen


def g1_description_dir() -> Path:
    """Return the folder holding ``urdf/`` and ``meshes/`` of the G1 description.

    The environment variable ``A2CF_G1_DESCRIPTION_DIR`` overrides the search (for a checkout of
    unitree_ros or a vendored copy with the same layout).

    Raises:
        RobotAssetError: when no installed example-robot-data holds the G1.
    """
    override = os.environ.get(_ENV_OVERRIDE)
    if override:
        path = Path(override)
        if not (path / "urdf" / G1_URDF_NAME).is_file():
            raise RobotAssetError(
                f"{_ENV_OVERRIDE}={override} does not contain urdf/{G1_URDF_NAME}. "
                f"Point it at a g1_description folder or unset it to use example-robot-data."
            )
        return path
    searched = []
    for root in _candidate_roots():
        path = root / _RELATIVE_DESCRIPTION_DIR
        searched.append(str(path))
        if (path / "urdf" / G1_URDF_NAME).is_file():
            return path
    raise RobotAssetError(
        f"The Unitree G1 model ({G1_URDF_NAME}) was not found. It ships with the "
        f"'example-robot-data' package (>= 5.0): run `pip install example-robot-data`. "
        f"Searched: {', '.join(searched)}. To use another copy, set {_ENV_OVERRIDE}."
    )


def g1_urdf_path() -> Path:
    """Path of the G1 29-DoF URDF (see :func:`g1_description_dir`)."""
    return g1_description_dir() / "urdf" / G1_URDF_NAME


def g1_mesh_dir() -> Path:
    """Folder of the G1 STL meshes referenced by the URDF as ``package://...``."""
    mesh_dir = g1_description_dir() / "meshes"
    if not mesh_dir.is_dir():
        raise RobotAssetError(
            f"The G1 meshes folder {mesh_dir} is missing; reinstall example-robot-data "
            f"(`pip install --force-reinstall example-robot-data`)."
        )
    return mesh_dir
