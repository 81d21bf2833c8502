"""Shared pytest fixtures: the G1 models are built once per session."""

from __future__ import annotations

import numpy as np
import pytest

from robots import MujocoModelConfig, build_mujoco_model, build_pinocchio_model


@pytest.fixture(scope="session")
def g1_pin():
    """The Pinocchio G1 (free-flyer)."""
    return build_pinocchio_model()


@pytest.fixture(scope="session")
def g1_mj():
    """The default MuJoCo G1 (actuators, floor, armature)."""
    return build_mujoco_model()


@pytest.fixture(scope="session")
def g1_mj_rigid():
    """A MuJoCo G1 with the same rigid-body model as Pinocchio: no armature, floor or actuators."""
    return build_mujoco_model(MujocoModelConfig(armature=False, floor=False, actuators=False))


@pytest.fixture
def rng():
    """A seeded random generator."""
    return np.random.default_rng(1234)
