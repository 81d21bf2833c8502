"""The Unitree G1 from one source for every consumer: Pinocchio, MuJoCo and the joint table.

Bottom of the import graph: nothing here imports ``optimal_control``, ``rl`` or ``a2cf_mb``.
"""

from robots import g1
from robots.assets import RobotAssetError, g1_mesh_dir, g1_urdf_path
from robots.mujoco_model import (
    MujocoModelConfig,
    build_mujoco_model,
    build_mujoco_spec,
    stand_data,
)
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

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
