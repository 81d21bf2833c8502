"""Domain randomisation: friction, payload and centre-of-mass offset written into each env's own
``MjModel`` copy (:class:`Randomizer`, the env's part; :class:`ModelRandomizer` writes one row).

Parameters are resampled for an env whenever it resets (or drawn once per shared copy, see
``RandomizationConfig.model_groups``); they are reported in the privileged observations in the
order of :data:`PARAM_NAMES`. Pushes are :mod:`rl.envs.pushes`.

The parameter rows live on the env's device; writing them into the ``MjModel`` copies (host
memory) copies the drawn rows to the host, at resets only (never in a step).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import torch

from robots import g1

if TYPE_CHECKING:
    from rl.envs.task_schema import RandomizationConfig

PARAM_NAMES = ("friction", "payload_kg", "com_offset_x_m", "com_offset_y_m", "com_offset_z_m")
"""Columns of the randomisation parameter tensor (N, 5)."""
NUM_PARAMS = len(PARAM_NAMES)
MODEL_FIELDS = ("geom_friction", "body_mass", "body_inertia", "body_ipos")
"""The ``MjModel`` fields :meth:`ModelRandomizer.apply` writes (a batched backend copies these)."""


def nominal_params(
    num_envs: int, model: mujoco.MjModel, device: torch.device | str = "cpu"
) -> torch.Tensor:
    """Parameters (N, 5) of the unrandomised model: its sole friction, no payload, no CoM offset."""
    params = torch.zeros(num_envs, NUM_PARAMS, device=device)
    params[:, 0] = float(model.geom_friction[model.geom(f"{g1.SOLE_FRAMES[0]}_0").id, 0])
    return params


def sample_params(num: int, cfg: RandomizationConfig, generator: torch.Generator) -> torch.Tensor:
    """Draw ``num`` parameter rows (num, 5) uniformly from the ranges of ``cfg`` (on the
    generator's device)."""
    dev = generator.device
    low = torch.tensor(
        [cfg.friction_range[0], cfg.payload_mass_range_kg[0]] + [cfg.com_offset_range_m[0]] * 3,
        device=dev,
    )
    high = torch.tensor(
        [cfg.friction_range[1], cfg.payload_mass_range_kg[1]] + [cfg.com_offset_range_m[1]] * 3,
        device=dev,
    )
    return low + (high - low) * torch.rand(num, NUM_PARAMS, generator=generator, device=dev)


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


class Randomizer:
    """The env's randomisation part: the model copies, their parameter rows (N, 5) and the draws.

    With ``model_groups == 0`` every env has its own copy, redrawn whenever it resets; with G > 0
    there are G copies drawn once (env i steps with copy i % G); disabled, every env steps with
    the nominal model and reports its nominal parameters.
    """

    def __init__(
        self,
        cfg: RandomizationConfig,
        model: mujoco.MjModel,
        num_envs: int,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """Copies of ``model`` for ``num_envs`` envs; group copies are drawn here. The parameter
        rows live on ``device`` (the generator's)."""
        self.cfg, self.generator, self.device = cfg, generator, device
        self.writer = ModelRandomizer.for_model(model, cfg.payload_body)
        if cfg.enabled:
            self.writer.check_payload_range(cfg.payload_mass_range_kg)
        self.per_env = cfg.enabled and cfg.model_groups == 0
        count = num_envs if cfg.model_groups == 0 else min(cfg.model_groups, num_envs)
        self.model_copies = [copy.copy(model) for _ in range(count)] if cfg.enabled else [model]
        self.models = [self.model_copies[i % len(self.model_copies)] for i in range(num_envs)]
        self.params = nominal_params(num_envs, model, device)
        if cfg.enabled and not self.per_env:
            groups = sample_params(count, cfg, generator)
            rows = groups.double().cpu().numpy()  # to the host MjModel copies, once
            for model_copy, row in zip(self.model_copies, rows, strict=True):
                self.writer.apply(model_copy, row)
            self.params = groups[torch.arange(num_envs, device=device) % count].clone()

    def reset(self, env_ids: torch.Tensor) -> None:
        """Per-env copies: draw and write fresh parameters for ``env_ids`` (M,)."""
        if not self.per_env:
            return
        params = sample_params(env_ids.numel(), self.cfg, self.generator)
        self.params[env_ids] = params
        rows = params.double().cpu().numpy()  # to the host MjModel copies: a reset-time copy
        for i, row in zip(env_ids.tolist(), rows, strict=True):
            self.writer.apply(self.models[i], row)

    def state_dict(self) -> dict[str, Any]:
        """The parameter rows (the copies are rebuilt from them)."""
        return {"params": self.params.clone()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the rows (onto this part's device) and write them into the copies."""
        self.params = state["params"].to(self.device, copy=True)
        if self.cfg.enabled:
            rows = self.params.double().cpu().numpy()
            for i, model_copy in enumerate(self.model_copies):
                self.writer.apply(model_copy, rows[i])
