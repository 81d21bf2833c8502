"""Domain randomisation: per-env friction, payload and centre-of-mass offset written into each env's
own ``MjModel`` copy, and pushes as base velocity kicks.

Parameters are resampled for an env whenever it resets; they are reported in the privileged
observations in the order of :data:`PARAM_NAMES`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import torch

from robots import g1

if TYPE_CHECKING:
    from rl.tasks.config import RandomizationConfig

PARAM_NAMES = ("friction", "payload_kg", "com_offset_x_m", "com_offset_y_m", "com_offset_z_m")
"""Columns of the randomisation parameter tensor (N, 5)."""
NUM_PARAMS = len(PARAM_NAMES)


def nominal_params(num_envs: int, model: mujoco.MjModel) -> torch.Tensor:
    """Parameters (N, 5) of the unrandomised model: its sole friction, no payload, no CoM offset."""
    params = torch.zeros(num_envs, NUM_PARAMS)
    params[:, 0] = float(model.geom_friction[model.geom(f"{g1.SOLE_FRAMES[0]}_0").id, 0])
    return params


def sample_params(num: int, cfg: RandomizationConfig, generator: torch.Generator) -> torch.Tensor:
    """Draw ``num`` parameter rows (num, 5) uniformly from the ranges of ``cfg``."""
    low = torch.tensor(
        [cfg.friction_range[0], cfg.payload_mass_range_kg[0]] + [cfg.com_offset_range_m[0]] * 3
    )
    high = torch.tensor(
        [cfg.friction_range[1], cfg.payload_mass_range_kg[1]] + [cfg.com_offset_range_m[1]] * 3
    )
    return low + (high - low) * torch.rand(num, NUM_PARAMS, generator=generator)


@dataclass(frozen=True)
class ModelRandomizer:
    """Writes parameter rows into env models, relative to the nominal model's values."""

    contact_geoms: (
        np.ndarray
    )  # ids of sole spheres and of the world's colliding geoms (floor, terrain)
    body: int  # id of the payload body
    nominal_mass_kg: float  # payload body mass without payload [kg]
    nominal_ipos_m: np.ndarray  # payload body CoM in its frame without offset [m], (3,)
    nominal_inertia: np.ndarray  # payload body principal inertia [kg m^2], (3,)

    @classmethod
    def for_model(cls, model: mujoco.MjModel, payload_body: str) -> ModelRandomizer:
        """Set up for ``model``; ``payload_body`` names the body receiving payload and CoM shift."""
        try:
            body = model.body(payload_body).id
        except KeyError as err:
            raise ValueError(
                f"randomization payload_body '{payload_body}' is not a body of the G1 model; use a link "
                f"name such as 'torso_link' or 'pelvis'."
            ) from err
        geoms = [model.geom(f"{s}_{i}").id for s in g1.SOLE_FRAMES for i in range(4)]
        # Floor and every terrain geom: the ground the soles touch, whatever the task built.
        world = (model.geom_bodyid == 0) & ((model.geom_contype | model.geom_conaffinity) != 0)
        geoms.extend(int(i) for i in np.flatnonzero(world))
        return cls(
            contact_geoms=np.array(geoms),
            body=body,
            nominal_mass_kg=float(model.body_mass[body]),
            nominal_ipos_m=model.body_ipos[body].copy(),
            nominal_inertia=model.body_inertia[body].copy(),
        )

    def check_payload_range(self, payload_mass_range_kg: tuple[float, float]) -> None:
        """Refuse a payload range that could leave the payload body with no mass."""
        if self.nominal_mass_kg + payload_mass_range_kg[0] <= 0:
            raise ValueError(
                f"EnvConfig.payload_mass_range_kg {payload_mass_range_kg} can remove more than the "
                f"payload body's {self.nominal_mass_kg:.2f} kg; raise its lower end (--task-randomization-payload-mass-range-kg)."
            )

    def apply(self, model: mujoco.MjModel, params: np.ndarray) -> None:
        """Write one parameter row (5,) into ``model`` (an env's own copy)."""
        friction, payload_kg = float(params[0]), float(params[1])
        model.geom_friction[self.contact_geoms, 0] = friction
        mass = self.nominal_mass_kg + payload_kg
        if mass <= 0:
            raise ValueError(
                f"Payload {payload_kg} kg leaves body {self.body} with mass {mass} kg; raise "
                f"the task's randomization payload_mass_range_kg."
            )
        model.body_mass[self.body] = mass
        # Scale the inertia with the mass (same shape, denser), keep it physical.
        model.body_inertia[self.body] = self.nominal_inertia * (mass / self.nominal_mass_kg)
        model.body_ipos[self.body] = self.nominal_ipos_m + params[2:5]
