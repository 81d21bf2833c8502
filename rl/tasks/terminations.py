"""Termination terms: pure functions of the batched :class:`EnvState`, each returning (N,) bool."""

from __future__ import annotations

import math

import torch

from rl.envs.state import EnvState
from rl.tasks.rewards import _contacts


def base_too_low(s: EnvState, min_height_m: float) -> torch.Tensor:
    """Pelvis below ``min_height_m`` [m]: the robot fell."""
    return s.base_pos_w[:, 2] < min_height_m


def base_tilted(s: EnvState, max_tilt_rad: float) -> torch.Tensor:
    """Pelvis z axis tilted more than ``max_tilt_rad`` [rad] from vertical."""
    # projected gravity z = -cos(tilt)
    return -s.projected_gravity_b[:, 2] < math.cos(max_tilt_rad)


def link_on_ground(s: EnvState, bodies: tuple[str, ...] = ()) -> torch.Tensor:
    """Any of the named links (all non-foot links when empty) touches the ground: a fall onto
    knees, hands, back (needs the task's ``scene.link_collisions``)."""
    return _contacts(s, bodies).any(dim=-1)
