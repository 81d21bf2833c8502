"""The Unitree G1 from one source for every consumer: Pinocchio, MuJoCo and the joint table.

Bottom of the import graph: nothing here imports ``optimal_control``, ``rl`` or ``a2cf_mb``.
The Pinocchio model (``G1Pinocchio``, ``build_pinocchio_model``) is imported on first use: the
simulator and training need MuJoCo only, and run where Pinocchio is not installed.
"""

from typing import TYPE_CHECKING, Any

from robots import g1
from robots.assets import RobotAssetError, g1_mesh_dir, g1_urdf_path
from robots.mujoco_model import (
    MujocoModelConfig,
    build_mujoco_model,
    build_mujoco_spec,
    stand_data,
)

if TYPE_CHECKING:
    from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

_PINOCCHIO_NAMES = ("G1Pinocchio", "build_pinocchio_model")


def __getattr__(name: str) -> Any:
    """``robots.G1Pinocchio`` and ``robots.build_pinocchio_model``, importing Pinocchio then."""
    if name in _PINOCCHIO_NAMES:
        from robots import pinocchio_model

        return getattr(pinocchio_model, name)
    raise AttributeError(f"module 'robots' has no attribute '{name}'")


__all__ = [
    "G1Pinocchio",
    "MujocoModelConfig",
    "RobotAssetError",
    "build_mujoco_model",
    "build_mujoco_spec",
    "build_pinocchio_model",
    "g1",
    "g1_mesh_dir",
    "g1_urdf_path",
    "stand_data",
]
