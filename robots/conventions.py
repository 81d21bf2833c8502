"""Conversions between Pinocchio's and MuJoCo's free-flyer conventions for the G1.

    Pinocchio  q = [p_w, quat xyzw, joints]   v = [v_b (pelvis frame), omega_b, qdot]
    MuJoCo  qpos = [p_w, quat wxyz, joints]  qvel = [v_w (world frame), omega_b, qdot]

Both place the 29 joints in the URDF order of :data:`robots.g1.JOINTS` (checked by the tests), so
only the base parts differ: the quaternion order and the frame of the base linear velocity.
Generalised forces transform with the transpose of the velocity map.
"""

from __future__ import annotations

import numpy as np


def quat_xyzw_to_wxyz(quat_xyzw: np.ndarray) -> np.ndarray:
    """Reorder quaternions (..., 4) from x, y, z, w to w, x, y, z."""
    return np.concatenate([quat_xyzw[..., 3:4], quat_xyzw[..., :3]], axis=-1)


def quat_wxyz_to_xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    """Reorder quaternions (..., 4) from w, x, y, z to x, y, z, w."""
    return np.concatenate([quat_wxyz[..., 1:4], quat_wxyz[..., 0:1]], axis=-1)


def quat_wxyz_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) in w, x, y, z order."""
    w, x, y, z = np.moveaxis(np.asarray(quat_wxyz, dtype=float), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def pin_to_mj_qpos(q: np.ndarray) -> np.ndarray:
    """Pinocchio configuration (..., 36) to MuJoCo qpos (..., 36)."""
    return np.concatenate([q[..., :3], quat_xyzw_to_wxyz(q[..., 3:7]), q[..., 7:]], axis=-1)


def mj_to_pin_q(qpos: np.ndarray) -> np.ndarray:
    """MuJoCo qpos (..., 36) to Pinocchio configuration (..., 36)."""
    return np.concatenate([qpos[..., :3], quat_wxyz_to_xyzw(qpos[..., 3:7]), qpos[..., 7:]], -1)


def pin_to_mj_qvel(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Pinocchio velocity (..., 35) at configuration q (..., 36) to MuJoCo qvel (..., 35)."""
    rot = quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q[..., 3:7]))
    lin_w = np.einsum("...ij,...j->...i", rot, v[..., :3])
    return np.concatenate([lin_w, v[..., 3:]], axis=-1)


def mj_to_pin_v(qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """MuJoCo qvel (..., 35) at qpos (..., 36) to Pinocchio velocity (..., 35)."""
    rot = quat_wxyz_to_matrix(qpos[..., 3:7])
    lin_b = np.einsum("...ji,...j->...i", rot, qvel[..., :3])
    return np.concatenate([lin_b, qvel[..., 3:]], axis=-1)


def velocity_map_pin_to_mj(q: np.ndarray) -> np.ndarray:
    """Matrix T (35, 35) with qvel_mj = T v_pin at Pinocchio configuration q (36,).

    Mass matrices and generalised forces map as M_pin = T^T M_mj T and tau_pin = T^T tau_mj.
    """
    t = np.eye(35)
    t[:3, :3] = quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q[3:7]))
    return t
