"""The symbolic CasADi dynamics agree with Pinocchio at random configurations of the G1."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optimal_control.casadi_dynamics import build_symbolic_dynamics
from robots.pinocchio_model import build_pinocchio_model

TOL = 1e-10


@pytest.fixture(scope="module")
def g1_symbolic():
    robot = build_pinocchio_model()
    return robot, build_symbolic_dynamics(robot.model, robot.frame_ids)


def _random_state(model: pin.Model, seed: int):
    rng = np.random.default_rng(seed)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q[:3] = rng.normal(size=3)
    return q, rng.normal(size=model.nv), rng.normal(size=model.nv), rng


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rnea_with_external_forces_matches_pinocchio(g1_symbolic, seed):
    robot, sym = g1_symbolic
    model = robot.model
    q, v, a, rng = _random_state(model, seed)
    fext = [pin.Force(rng.normal(size=6) * 10.0) for _ in range(model.njoints)]
    tau_pin = pin.rnea(model, model.createData(), q, v, a, fext)
    fext_flat = np.concatenate([f.vector for f in fext])
    tau_sym = np.asarray(sym.rnea(q, v, a, fext_flat)).ravel()
    assert np.abs(tau_sym - tau_pin).max() < TOL * max(1.0, np.abs(tau_pin).max())


@pytest.mark.parametrize("seed", [3, 4])
def test_mass_matrix_com_and_energy_match_pinocchio(g1_symbolic, seed):
    robot, sym = g1_symbolic
    model = robot.model
    data = model.createData()
    q, v, _, _ = _random_state(model, seed)
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    assert np.abs(np.asarray(sym.mass_matrix(q)) - mass).max() < TOL
    com = pin.centerOfMass(model, data, q)
    assert np.abs(np.asarray(sym.com(q)).ravel() - com).max() < TOL
    e_kin = pin.computeKineticEnergy(model, data, q, v)
    assert abs(float(sym.kinetic_energy(q, v)) - e_kin) < TOL * max(1.0, e_kin)


@pytest.mark.parametrize("seed", [5, 6])
def test_frame_kinematics_and_jacobians_match_pinocchio(g1_symbolic, seed):
    robot, sym = g1_symbolic
    model = robot.model
    data = model.createData()
    q, v, _, _ = _random_state(model, seed)
    pin.forwardKinematics(model, data, q, v)
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data, q)
    for name in ("pelvis", "left_sole", "right_sole", "left_hand"):
        fid = robot.frame_ids[name]
        rot, pos = sym.frame_placement[name](q)
        assert np.abs(np.asarray(pos).ravel() - data.oMf[fid].translation).max() < TOL
        assert np.abs(np.asarray(rot) - data.oMf[fid].rotation).max() < TOL
        jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        assert np.abs(np.asarray(sym.frame_jacobian[name](q)) - jac).max() < TOL
        vel = pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        lin, ang = sym.frame_velocity[name](q, v)
        assert np.abs(np.asarray(lin).ravel() - vel.linear).max() < TOL
        assert np.abs(np.asarray(ang).ravel() - vel.angular).max() < TOL


def test_unsupported_joint_type_is_named():
    model = pin.Model()
    model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    with pytest.raises(NotImplementedError, match="ball"):
        build_symbolic_dynamics(model)
