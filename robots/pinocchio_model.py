"""The G1 as a Pinocchio model with a free-flyer root and the operational frames of :mod:`robots.g1`.

Pinocchio conventions (kept throughout the optimal-control code):
    q = [p_w (3), quat_xyzw (4), joints (29)]           shape (36,)
    v = [v_b (3), omega_b (3), joint velocities (29)]   shape (35,), base twist in the pelvis frame
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from robots import g1
from robots.assets import g1_urdf_path


@dataclass(frozen=True)
class G1Pinocchio:
    """A Pinocchio G1 with handy indices. Create with :func:`build_pinocchio_model`."""

    model: pin.Model
    frame_ids: dict[str, int]  # operational frame name -> frame index
    joint_q_index: np.ndarray  # (29,) index in q of each joint of g1.JOINTS
    joint_v_index: np.ndarray  # (29,) index in v of each joint of g1.JOINTS
    q_stand: np.ndarray  # (36,) standing configuration, soles on z = 0
    position_lower_rad: np.ndarray  # (29,) joint lower limits from the URDF [rad]
    position_upper_rad: np.ndarray  # (29,) joint upper limits from the URDF [rad]
    velocity_limit_rad_s: np.ndarray  # (29,) joint speed limits from the URDF [rad/s]

    @property
    def total_mass_kg(self) -> float:
        """Total mass [kg]."""
        return float(sum(inertia.mass for inertia in self.model.inertias))

    def data(self) -> pin.Data:
        """A fresh ``pin.Data`` for this model."""
        return self.model.createData()

    def frame_placement(self, q: np.ndarray, frame: str, data: pin.Data | None = None) -> pin.SE3:
        """World placement of an operational frame at configuration ``q`` (36,)."""
        data = data or self.data()
        pin.framesForwardKinematics(self.model, data, q)
        return data.oMf[self.frame_ids[frame]].copy()

    def configuration(
        self, joint_pos_rad: np.ndarray, base_pos_w: np.ndarray, base_quat_xyzw: np.ndarray
    ) -> np.ndarray:
        """Assemble q (36,) from joint angles (29,), base position (3,) and quaternion xyzw (4,)."""
        q = np.zeros(self.model.nq)
        q[:3] = base_pos_w
        q[3:7] = base_quat_xyzw
        q[self.joint_q_index] = joint_pos_rad
        return q


def _add_operational_frames(model: pin.Model) -> dict[str, int]:
    ids: dict[str, int] = {}
    for spec in g1.FRAMES:
        if not model.existFrame(spec.link):
            raise ValueError(f"URDF link '{spec.link}' of frame '{spec.name}' is not in the model.")
        link = model.frames[model.getFrameId(spec.link)]
        placement = link.placement * pin.SE3(np.eye(3), np.asarray(spec.offset_m, dtype=float))
        frame = pin.Frame(
            spec.name, link.parentJoint, model.getFrameId(spec.link), placement, pin.OP_FRAME
        )
        ids[spec.name] = model.addFrame(frame)
    return ids


def _standing_configuration(model: pin.Model, joint_q_index: np.ndarray, sole_ids) -> np.ndarray:
    q = pin.neutral(model)
    q[joint_q_index] = g1.STAND_JOINT_POS_RAD
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    lowest_sole_z = min(data.oMf[i].translation[2] for i in sole_ids)
    q[2] -= lowest_sole_z
    return q


@lru_cache(maxsize=1)
def build_pinocchio_model() -> G1Pinocchio:
    """Build (once per process) the free-flyer Pinocchio model of the G1 29-DoF URDF."""
    model = pin.buildModelFromUrdf(str(g1_urdf_path()), pin.JointModelFreeFlyer())
    frame_ids = _add_operational_frames(model)
    names = list(model.names)
    missing = [j.name for j in g1.JOINTS if j.name not in names]
    if missing:
        raise ValueError(f"The G1 URDF lacks joints {missing}; is it the 29-DoF revision 1.0?")
    joint_ids = [model.getJointId(j.name) for j in g1.JOINTS]
    q_index = np.array([model.joints[i].idx_q for i in joint_ids])
    v_index = np.array([model.joints[i].idx_v for i in joint_ids])
    sole_ids = [frame_ids[name] for name in g1.SOLE_FRAMES]
    return G1Pinocchio(
        model=model,
        frame_ids=frame_ids,
        joint_q_index=q_index,
        joint_v_index=v_index,
        q_stand=_standing_configuration(model, q_index, sole_ids),
        position_lower_rad=model.lowerPositionLimit[q_index].copy(),
        position_upper_rad=model.upperPositionLimit[q_index].copy(),
        velocity_limit_rad_s=model.velocityLimit[v_index].copy(),
    )
