"""The physics model the batched envs step, and where things live in its state and sensor rows.

The env steps a *collision-primitive* G1: :func:`robots.mujoco_model.build_mujoco_spec` with the link
meshes removed (their inertials come from the URDF, the meshes carry no mass), the 8 sole spheres,
and, when the task's scene asks for it (the default), capsules/boxes fitted to the link meshes
(:mod:`robots.collision_primitives`) that collide with the floor and terrain but not with each other:
shins hit stair edges, knees and hands touch the floor in a failed flip, a fallen robot lies on the
ground. Why not the meshes: a compiled model with meshes is ~36 MB per copy (collision
structures), which rules out one randomised model per env (512 envs would need ~18 GB). A task's
terrain hook adds its geoms to the same spec. Joint torques are added as ``actuatorfrc`` sensors so
rewards see the actual (clamped) actuator forces.

States are ``mjSTATE_FULLPHYSICS`` rows; controls are ``mjSTATE_CTRL | mjSTATE_XFRC_APPLIED`` rows
(29 joint targets, then ``xfrc_applied`` of every body: world-frame force [N] and torque [Nm] at
the body's centre of mass).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from robots import g1
from robots.mujoco_model import STAND_KEYFRAME, MujocoModelConfig, build_mujoco_spec

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
CONTROL_SPEC = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED
TORQUE_SENSOR_PREFIX = "torque_"
CONTACT_SENSOR_PREFIX = "ground_contact_"
FOOT_BODIES = ("left_ankle_pitch_link", "left_ankle_roll_link", "right_ankle_pitch_link",
               "right_ankle_roll_link")  # fmt: skip
"""Bodies whose ground contact is the soles' job (not reported as link contacts)."""
CONTACT_FOUND = 1
"""mjSENS_CONTACT data spec: the number of matching contacts ("found")."""


def contact_bodies(model: mujoco.MjModel) -> tuple[str, ...]:
    """Bodies with a colliding geom other than the feet: their ground contacts are reported."""
    names = []
    for body in range(1, model.nbody):
        name = model.body(body).name
        geoms = np.flatnonzero(model.geom_bodyid == body)
        if name not in FOOT_BODIES and any(model.geom_contype[g] for g in geoms):
            names.append(name)
    return tuple(names)


def build_physics_model(
    cfg: MujocoModelConfig = MujocoModelConfig(),
    link_collisions: bool = True,
    terrain: Callable[[mujoco.MjSpec], None] | None = None,
    tracked_bodies: tuple[str, ...] = (),
) -> mujoco.MjModel:
    """Compile the mesh-free G1 the envs step (a fresh, writable model on every call).

    Args:
        cfg: the G1 model options (physics step, floor, sole spheres).
        link_collisions: add the fitted link primitives (collide with floor and terrain).
        terrain: hook adding terrain geoms to the spec before compiling.
        tracked_bodies: links whose frame pose and velocity become sensors (a tracking task's
            bodies, :func:`add_body_sensors`); none: the model is as without them.
    """
    spec = build_mujoco_spec(cfg)
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    if link_collisions:
        from robots.collision_primitives import add_link_primitives, fit_link_primitives

        add_link_primitives(spec, fit_link_primitives())
    if terrain is not None:
        terrain(spec)
    for joint in g1.JOINTS:
        spec.add_sensor(
            name=TORQUE_SENSOR_PREFIX + joint.name,
            type=mujoco.mjtSensor.mjSENS_ACTUATORFRC,
            objtype=mujoco.mjtObj.mjOBJ_ACTUATOR,
            objname=joint.name,
        )
    for sole in g1.SOLE_FRAMES:
        spec.add_sensor(
            name=f"{sole}_vel",
            type=mujoco.mjtSensor.mjSENS_FRAMELINVEL,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=sole,
        )
    # Link-ground contacts (knees, hands, torso, ...): one "found" count per body. The link
    # primitives collide with the ground only, so any contact of theirs is a ground contact.
    for body in contact_bodies(spec.compile()):
        sensor = spec.add_sensor(
            name=CONTACT_SENSOR_PREFIX + body,
            type=mujoco.mjtSensor.mjSENS_CONTACT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            objname=body,
        )
        sensor.intprm[:3] = [CONTACT_FOUND, 0, 1]
    add_body_sensors(spec, tracked_bodies)
    return spec.compile()


BODY_SENSORS = (
    ("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
    ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT),
    ("linvel", mujoco.mjtSensor.mjSENS_FRAMELINVEL),
    ("angvel", mujoco.mjtSensor.mjSENS_FRAMEANGVEL),
)
"""Per tracked body: its link frame's world position [m], orientation (w x y z), linear and
angular velocity (world frame) [m/s, rad/s], as ``body_<kind>_<name>`` sensors."""


def add_body_sensors(spec: mujoco.MjSpec, bodies: tuple[str, ...]) -> None:
    """Add the :data:`BODY_SENSORS` of each link in ``bodies`` (its frame, not its CoM)."""
    names = {b.name for b in spec.bodies}
    unknown = [b for b in bodies if b not in names]
    if unknown:
        raise ValueError(f"tracked bodies {unknown} are not G1 links; links: {sorted(names)}")
    for kind, sensor_type in BODY_SENSORS:
        for body in bodies:
            spec.add_sensor(
                name=f"body_{kind}_{body}",
                type=sensor_type,
                objtype=mujoco.mjtObj.mjOBJ_XBODY,
                objname=body,
            )


def _state_offset(model: mujoco.MjModel, component: mujoco.mjtState) -> int:
    """Offset of one component inside a FULLPHYSICS state row (components are stored in bit order)."""
    offset = 0
    bit = 1
    while bit < int(component):
        if int(STATE_SPEC) & bit:
            offset += mujoco.mj_stateSize(model, bit)
        bit <<= 1
    return offset


def _sensor_slice(model: mujoco.MjModel, name: str) -> slice:
    sensor = model.sensor(name)
    start = int(sensor.adr[0])
    return slice(start, start + int(sensor.dim[0]))


@dataclass(frozen=True)
class ModelLayout:
    """Column indices into state, control and sensor rows of the physics model."""

    nstate: int  # length of a FULLPHYSICS state row
    ncontrol: int  # length of a CTRL | XFRC_APPLIED control row
    nsensordata: int  # length of a sensor row
    time: int  # state column of the simulation time [s]
    qpos: slice  # state columns of qpos (36): p_w, quat wxyz, 29 joints
    qvel: slice  # state columns of qvel (35): v_w, omega_b, 29 joint rates
    ctrl: slice  # control columns of the 29 joint targets [rad]
    pelvis_wrench: slice  # control columns of the pelvis xfrc_applied: force_w [N], torque_w [Nm]
    pelvis_body: int  # MuJoCo body id of the pelvis
    foot_touch: tuple[int, int]  # sensor columns of left / right sole normal force [N]
    foot_pos: tuple[slice, slice]  # sensor columns of left / right sole position p_w [m]
    foot_vel: tuple[slice, slice]  # sensor columns of left / right sole linear velocity v_w [m/s]
    torque: slice  # sensor columns of the 29 actuator forces [Nm]
    contact: np.ndarray  # sensor columns of the link-ground contact counts, one per contact body
    contact_bodies: tuple[str, ...]  # names of the bodies of ``contact``
    joint_range_rad: np.ndarray  # (29, 2) position limits of the actuated joints [rad]
    tracked_bodies: tuple[str, ...]  # links with body sensors (K), see add_body_sensors
    body_pos: np.ndarray  # (K, 3) sensor columns of their frame positions p_w [m]
    body_quat: np.ndarray  # (K, 4) sensor columns of their orientations, w x y z
    body_lin_vel: np.ndarray  # (K, 3) sensor columns of their linear velocities v_w [m/s]
    body_ang_vel: np.ndarray  # (K, 3) sensor columns of their angular velocities w_w [rad/s]
    stand_state: np.ndarray  # FULLPHYSICS row of the standing keyframe, shape (nstate,)


def model_layout(model: mujoco.MjModel) -> ModelLayout:
    """Index the state, control and sensor rows of a model from :func:`build_physics_model`."""
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    qpos0 = _state_offset(model, mujoco.mjtState.mjSTATE_QPOS)
    qvel0 = _state_offset(model, mujoco.mjtState.mjSTATE_QVEL)
    pelvis = model.body(g1.BASE_LINK).id
    xfrc0 = model.nu
    torque_sensors = [_sensor_slice(model, TORQUE_SENSOR_PREFIX + j.name) for j in g1.JOINTS]
    if any(s.start != torque_sensors[0].start + i for i, s in enumerate(torque_sensors)):
        raise RuntimeError("Torque sensors are not contiguous; rebuild with build_physics_model().")
    bodies = tuple(
        model.sensor(i).name[len(CONTACT_SENSOR_PREFIX) :]
        for i in range(model.nsensor)
        if model.sensor(i).name.startswith(CONTACT_SENSOR_PREFIX)
    )
    tracked = tuple(
        model.sensor(i).name[len("body_pos_") :]
        for i in range(model.nsensor)
        if model.sensor(i).name.startswith("body_pos_")
    )

    def body_columns(kind: str, width: int) -> np.ndarray:
        cols = [np.arange(width) + _sensor_slice(model, f"body_{kind}_{b}").start for b in tracked]
        return np.array(cols, dtype=int).reshape(len(tracked), width)

    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    stand = np.empty(nstate)
    mujoco.mj_getState(model, data, stand, STATE_SPEC)
    return ModelLayout(
        nstate=nstate,
        ncontrol=mujoco.mj_stateSize(model, CONTROL_SPEC),
        nsensordata=model.nsensordata,
        time=_state_offset(model, mujoco.mjtState.mjSTATE_TIME),
        qpos=slice(qpos0, qpos0 + model.nq),
        qvel=slice(qvel0, qvel0 + model.nv),
        ctrl=slice(0, model.nu),
        pelvis_wrench=slice(xfrc0 + 6 * pelvis, xfrc0 + 6 * pelvis + 6),
        pelvis_body=pelvis,
        foot_touch=tuple(_sensor_slice(model, f"{s}_touch").start for s in g1.SOLE_FRAMES),
        foot_pos=tuple(_sensor_slice(model, f"{s}_pos") for s in g1.SOLE_FRAMES),
        foot_vel=tuple(_sensor_slice(model, f"{s}_vel") for s in g1.SOLE_FRAMES),
        torque=slice(torque_sensors[0].start, torque_sensors[-1].stop),
        contact=np.array(
            [_sensor_slice(model, CONTACT_SENSOR_PREFIX + b).start for b in bodies], dtype=int
        ),
        contact_bodies=bodies,
        joint_range_rad=np.array([model.joint(j.name).range for j in g1.JOINTS]),
        tracked_bodies=tracked,
        body_pos=body_columns("pos", 3),
        body_quat=body_columns("quat", 4),
        body_lin_vel=body_columns("linvel", 3),
        body_ang_vel=body_columns("angvel", 3),
        stand_state=stand,
    )
