"""The G1 as a MuJoCo model built with ``mujoco.MjSpec`` from the same URDF as Pinocchio.

What the URDF import lacks and is added here: a free joint on the pelvis, resolved mesh paths,
position actuators with the G1 gains, effort limits and armature of :mod:`robots.g1`, sole contact
spheres, a floor, IMU / sole / hand sites and sensors, a standing keyframe and a tracking camera.

Actuators are MuJoCo *position* actuators (``kp``, ``kv``, ``forcerange`` = effort limit): the PD law
runs inside the integrator, so with ``implicitfast`` the damping term is integrated implicitly and the
model stays stable at dt = 0.005 s without PD in Python at every physics substep. Feed-forward torques
(e.g. from trajectory optimisation) go through ``qfrc_applied``; the assistive pelvis wrench through
``xfrc_applied`` of the pelvis body.

Contacts: the URDF collision meshes touch only the floor (a fallen robot lies on the ground) unless
``self_collision`` also makes them collide with each other; each sole has four spheres at the corners of the sole rectangle. Spheres on a plane are the cheapest and most stable
contact MuJoCo has, and four corners give a proper support polygon (centre of pressure) per foot.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np

from robots import g1
from robots.assets import g1_mesh_dir, g1_urdf_path

STAND_KEYFRAME = "stand"
FLOOR_GEOM = "floor"
TRACKING_CAMERA = "track"


@dataclass(frozen=True)
class MujocoModelConfig:
    """Options of the MuJoCo G1 model."""

    timestep_s: float = 0.005  # physics step [s]
    sole_sphere_radius_m: float = 0.01  # radius of the 4 contact spheres per sole [m]
    friction: float = 1.0  # sliding friction coefficient of soles and floor [-]
    self_collision: bool = False  # collide link meshes with each other (slower)
    body_floor_collision: bool = True  # link meshes hit the floor when the robot falls
    floor: bool = True  # add a ground plane at z = 0
    armature: bool = True  # add rotor armature to the joints (False only for model checks)
    actuators: bool = True  # add position actuators (False for a passive model)


def _sites_for_frames(spec: mujoco.MjSpec) -> None:
    for frame in g1.FRAMES:
        body = spec.body(frame.link)
        if body is None:
            raise ValueError(f"URDF link '{frame.link}' of frame '{frame.name}' not in the spec.")
        body.add_site(name=frame.name, pos=list(frame.offset_m), size=[0.01, 0.01, 0.01])


def _soles(spec: mujoco.MjSpec, cfg: MujocoModelConfig) -> None:
    radius = cfg.sole_sphere_radius_m
    centre = np.asarray(g1.SOLE_CENTER_OFFSET_M)
    for frame in g1.SOLE_FRAMES:
        link = next(f.link for f in g1.FRAMES if f.name == frame)
        body = spec.body(link)
        for i, corner in enumerate(g1.sole_corners_m()):
            pos = centre + corner + np.array([0.0, 0.0, radius])  # sphere bottom on the sole plane
            body.add_geom(
                name=f"{frame}_{i}",
                type=mujoco.mjtGeom.mjGEOM_SPHERE,
                size=[radius, 0, 0],
                pos=pos.tolist(),
                contype=1,
                conaffinity=1,
                condim=3,
                friction=[cfg.friction, 0.005, 0.0001],
                group=3,
                rgba=[0.9, 0.3, 0.1, 1.0],
            )
        # Touch-sensor zone covering the sole.
        body.add_site(
            name=f"{frame}_touch",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=(centre + np.array([0.0, 0.0, radius])).tolist(),
            size=[g1.SOLE_HALF_LENGTH_M + radius, g1.SOLE_HALF_WIDTH_M + 2 * radius, 2 * radius],
            group=4,
        )


def _actuators(spec: mujoco.MjSpec, cfg: MujocoModelConfig) -> None:
    for j in g1.JOINTS:
        joint = spec.joint(j.name)
        if cfg.armature:
            joint.armature = j.motor.armature
        if not cfg.actuators:
            continue
        act = spec.add_actuator(name=j.name, target=j.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=j.motor.kp, kv=j.motor.kd)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-j.motor.effort_nm, j.motor.effort_nm]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE


def _sensors(spec: mujoco.MjSpec) -> None:
    obj = mujoco.mjtObj.mjOBJ_SITE
    imu = "imu_pelvis"
    spec.add_sensor(name="imu_gyro", type=mujoco.mjtSensor.mjSENS_GYRO, objtype=obj, objname=imu)
    spec.add_sensor(
        name="imu_accel", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objtype=obj, objname=imu
    )
    spec.add_sensor(
        name="imu_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=obj, objname=imu
    )
    for frame in g1.SOLE_FRAMES:
        spec.add_sensor(
            name=f"{frame}_touch",
            type=mujoco.mjtSensor.mjSENS_TOUCH,
            objtype=obj,
            objname=f"{frame}_touch",
        )
        spec.add_sensor(
            name=f"{frame}_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=obj, objname=frame
        )


def _world(spec: mujoco.MjSpec, cfg: MujocoModelConfig) -> None:
    spec.option.timestep = cfg.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    world = spec.worldbody
    world.add_light(pos=[0, 0, 3.0], dir=[0, 0, -1], diffuse=[0.7, 0.7, 0.7], castshadow=False)
    if cfg.floor:
        tex = spec.add_texture(
            name="grid",
            type=mujoco.mjtTexture.mjTEXTURE_2D,
            builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
            rgb1=[0.2, 0.3, 0.4],
            rgb2=[0.1, 0.2, 0.3],
            width=300,
            height=300,
        )
        mat = spec.add_material(name="grid", texrepeat=[8, 8], reflectance=0.1)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
        world.add_geom(
            name=FLOOR_GEOM,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0, 0, 0.05],
            material="grid",
            contype=1,
            conaffinity=3,
            friction=[cfg.friction, 0.005, 0.0001],
        )


def _kinematic_model(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """``spec`` compiled for kinematics only: no geom, no mesh to load or process."""
    kinematic = spec.copy()
    for geom in list(kinematic.geoms):
        kinematic.delete(geom)
    for mesh in list(kinematic.meshes):
        kinematic.delete(mesh)
    return kinematic.compile()


def sole_corner_heights_mj(qpos: np.ndarray, spec: mujoco.MjSpec | None = None) -> np.ndarray:
    """Lowest sole-corner height per frame and sole (T, 2) [m] at MuJoCo configurations ``qpos``
    (T, nq): the heights of :func:`optimal_control.motion_clip.sole_corner_heights_m` (a test
    checks they agree), computed with MuJoCo alone, so the tracking task's motion library needs no
    Pinocchio (the lent GPU machine has none)."""
    model = _kinematic_model(spec if spec is not None else build_mujoco_spec())
    data = mujoco.MjData(model)
    corners = g1.sole_corners_m()
    heights = np.empty((qpos.shape[0], len(g1.SOLE_FRAMES)))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        for s, name in enumerate(g1.SOLE_FRAMES):
            site = data.site(name)
            heights[t, s] = (corners @ site.xmat.reshape(3, 3).T + site.xpos)[:, 2].min()
    return heights


def standing_qpos(spec: mujoco.MjSpec) -> np.ndarray:
    """The standing configuration (nq,) of a G1 spec with its sole sites: the joints at
    :data:`robots.g1.STAND_JOINT_POS_RAD`, the pelvis upright above the origin and lowered until
    the lower sole touches z = 0. The same pose as the Pinocchio model's ``q_stand`` (a test
    checks it), computed with MuJoCo alone, so the simulator needs no Pinocchio."""
    model = _kinematic_model(spec)
    data = mujoco.MjData(model)
    data.qpos[:] = 0.0
    data.qpos[3] = 1.0  # free joint: identity orientation (w, x, y, z)
    for joint, angle_rad in zip(g1.JOINTS, g1.STAND_JOINT_POS_RAD, strict=True):
        data.joint(joint.name).qpos[0] = angle_rad
    mujoco.mj_kinematics(model, data)
    data.qpos[2] -= min(data.site(name).xpos[2] for name in g1.SOLE_FRAMES)
    return data.qpos.copy()


def build_mujoco_spec(cfg: MujocoModelConfig = MujocoModelConfig()) -> mujoco.MjSpec:
    """Build the editable ``MjSpec`` of the G1 (compile it with ``spec.compile()``)."""
    # Keep the URDF's visual meshes (MuJoCo discards them by default) and strip package:// paths.
    urdf = re.sub(
        r"(<robot[^>]*>)",
        r'\1<mujoco><compiler discardvisual="false" strippath="true"/></mujoco>',
        g1_urdf_path().read_text(),
        count=1,
    )
    spec = mujoco.MjSpec.from_string(urdf)
    spec.meshdir = str(g1_mesh_dir())
    for mesh in spec.meshes:
        mesh.file = os.path.basename(mesh.file)
    pelvis = spec.body(g1.BASE_LINK)
    pelvis.add_freejoint(name="floating_base")
    pelvis.add_camera(
        name=TRACKING_CAMERA,
        mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM,
        pos=[0.0, -3.0, 0.3],
        xyaxes=[1, 0, 0, 0, 0, 1],
    )
    collide_floor = cfg.body_floor_collision or cfg.self_collision
    for geom in list(spec.geoms):
        if geom.contype == 0 and geom.conaffinity == 0:
            geom.group = 1  # URDF visual mesh
        elif geom.type == mujoco.mjtGeom.mjGEOM_SPHERE:
            spec.delete(geom)  # the URDF's tiny 5 mm sole spheres; replaced by _soles
        else:
            # URDF collision mesh / cylinder. Floor: contype 1, conaffinity 3; these: contype 2
            # (-> floor) and conaffinity 2 (-> each other, only with self_collision).
            geom.contype = 2 if collide_floor else 0
            geom.conaffinity = 2 if cfg.self_collision else 0
            geom.group = 3
    _sites_for_frames(spec)
    _soles(spec, cfg)
    _actuators(spec, cfg)
    _sensors(spec)
    _world(spec, cfg)
    key = spec.add_key(name=STAND_KEYFRAME, qpos=standing_qpos(spec).tolist())
    if cfg.actuators:
        key.ctrl = g1.STAND_JOINT_POS_RAD.tolist()
    return spec


@lru_cache(maxsize=8)
def build_mujoco_model(cfg: MujocoModelConfig = MujocoModelConfig()) -> mujoco.MjModel:
    """Compile (once per config and process) the MuJoCo G1. Treat the result as read-only."""
    return build_mujoco_spec(cfg).compile()


def stand_data(model: mujoco.MjModel) -> mujoco.MjData:
    """A fresh ``MjData`` reset to the standing keyframe, kinematics computed."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    return data
