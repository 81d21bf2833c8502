"""What a deployment bundle says beyond the policy's interface: the physics model the policy was
trained in, how its episodes start and end, and, for a tracking policy, the reference it reads.

:func:`rl.agents.export.deployment_bundle` writes these into ``policy.json``; a tracking policy's
reference goes beside it as ``reference.npz`` (:func:`write_reference`). With them, a script that
knows only MuJoCo, onnxruntime and numpy (``a2cf_mb/deploy/run_bundle.py``) rebuilds the training
env's G1 from the URDF and plays the policy, nothing else to rebuild:

* ``model``: the URDF it starts from (name and sha256), the simulator options, per joint the
  armature, damping and friction loss, the actuator law, every colliding geom of the training
  model (sole spheres, fitted link primitives, floor: type, size, pose in its body, friction,
  contact flags) and the standing keyframe.
* ``episode``: its length cap, the initial-state noise, the terminations (function and
  parameters), the domain randomisation the policy was trained with (a deployer's margin).
* ``reference`` (tracking tasks): the layout of ``reference.npz``: per 50 Hz frame the joint
  targets and rates, the tracked links' world poses and velocities, the feed-forward torques, the
  start state and floor shift, the phase; held ends included, MuJoCo conventions (quaternions
  w x y z, ``qvel``'s angular part in the pelvis frame).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

REFERENCE_FILE = "reference.npz"
"""A tracking policy's reference, beside ``policy.json``."""

GEOM_FIELDS = ("size", "pos", "quat", "contype", "conaffinity", "condim", "friction", "solref",
               "solimp", "margin", "gap", "priority", "solmix")  # fmt: skip
"""The compiled model's ``geom_<field>`` arrays a colliding geom is described by (those other
than :data:`GEOM_ALWAYS` only where they differ from MuJoCo's default geom)."""
GEOM_ALWAYS = ("size", "pos", "quat")
"""The geom fields every entry has."""

OPTION_FIELDS = ("timestep", "integrator", "cone", "solver", "iterations", "ls_iterations",
                 "tolerance", "impratio", "gravity", "disableflags", "enableflags", "noslip_iterations",
                 "jacobian")  # fmt: skip
"""The ``mjOption`` fields the training model sets or leaves at MuJoCo's defaults."""


def _plain(value: Any) -> Any:
    """A JSON-ready copy of a numpy scalar or array (full float precision)."""
    array = np.asarray(value)
    return array.tolist() if array.ndim else array.item()


OPTION_ENUMS = {"integrator": mujoco.mjtIntegrator, "cone": mujoco.mjtCone,
                "solver": mujoco.mjtSolver, "jacobian": mujoco.mjtJacobian}  # fmt: skip
"""The options written by their MuJoCo enum names (``mjINT_IMPLICITFAST``), not numbers."""


def _option(opt: Any, field: str) -> Any:
    """One ``mjOption`` field as JSON: an enum by its name, a number or vector as it is."""
    value = getattr(opt, field)
    return OPTION_ENUMS[field](value).name if field in OPTION_ENUMS else _plain(value)


def write_bundle_json(path: str | Path, description: dict[str, Any]) -> Path:
    """Write ``policy.json``: indented, each list of plain numbers on one line (a geom's size, a
    frame of the feed-forward table), which keeps the file a few times smaller than one number
    per line; floats keep their full precision."""
    from optimal_control.files import atomic_write_text

    text = json.dumps(description, indent=2)
    text = re.sub(r"\[([-+0-9.eE,\s]*)\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text)
    return atomic_write_text(path, text + "\n")


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def model_facts(env: Any) -> dict[str, Any]:
    """The ``model`` section: what rebuilds ``env``'s nominal physics model from the G1 URDF."""
    from robots import g1
    from robots.assets import G1_URDF_NAME, g1_urdf_path

    model = env.physics.model
    default = mujoco.MjSpec().worldbody.add_geom()  # a field at its default is left out
    geoms = []
    for g in range(model.ngeom):
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        geom_type = mujoco.mjtGeom(model.geom_type[g])
        if geom_type in (mujoco.mjtGeom.mjGEOM_MESH, mujoco.mjtGeom.mjGEOM_HFIELD):
            continue  # a terrain's heightfield or mesh: `terrain` says the scene is not flat
        entry = {
            "name": model.geom(g).name,
            "body": model.body(model.geom_bodyid[g]).name,
            "type": geom_type.name.removeprefix("mjGEOM_").lower(),
        }
        for field in GEOM_FIELDS:
            value = _plain(getattr(model, f"geom_{field}")[g])
            if field in GEOM_ALWAYS or value != _plain(getattr(default, field)):
                entry[field] = value
        geoms.append(entry)
    types = {mujoco.mjtGeom(t) for t in model.geom_type}
    dofs = [model.joint(j.name).dofadr[0] for j in g1.JOINTS]
    return {
        "urdf": G1_URDF_NAME,
        "urdf_sha256": sha256_file(g1_urdf_path()),
        "urdf_source": "example-robot-data (robots/g1_description/urdf), imported by MuJoCo's "
        "URDF compiler; then every URDF geom and mesh removed, a free joint 'floating_base' added "
        "on the pelvis, and the geoms, joints and actuators below added",
        "total_mass_kg": float(model.body_mass.sum()),
        "options": {f: _option(model.opt, f) for f in OPTION_FIELDS},
        "joints": [
            {
                "name": j.name,
                "armature_kgm2": float(model.dof_armature[d]),
                "damping_nms": float(model.dof_damping[d]),
                "frictionloss_nm": float(model.dof_frictionloss[d]),
            }
            for j, d in zip(g1.JOINTS, dofs, strict=True)
        ],
        "actuator": "one MuJoCo position actuator per joint (kp, kv = kd of `joints`, forcerange "
        "+-effort_limit_nm, ctrl = target_rad): the PD law runs inside the integrator",
        "geoms": geoms,
        "geom_defaults": "a field left out of a geom is at MuJoCo's default (MjSpec's add_geom)",
        "terrain": "flat"
        if mujoco.mjtGeom.mjGEOM_HFIELD not in types and len(geoms) == _flat_geoms(model)
        else "not flat: the training scene had terrain geoms beyond the floor",
        "stand_qpos": env.physics.stand_qpos.tolist(),
        "contact_bodies": list(env.physics.layout.contact_bodies),
    }


def _flat_geoms(model: mujoco.MjModel) -> int:
    """How many colliding geoms a flat scene has: the floor plus the robot's."""
    world = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0]
    robot = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0]
    planes = [g for g in world if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]
    return len(planes) + len(robot) if len(planes) == len(world) else -1


def episode_facts(env: Any) -> dict[str, Any]:
    """The ``episode`` section: start, end and the training distribution of ``env``'s task."""
    task = env.task
    init = task.initial_state
    return {
        "max_steps": env.max_episode_length,
        "length_cap_s": task.episode_length_s,
        "initial_state": {
            "joint_pos_noise_rad": init.joint_pos_noise_rad,
            "base_vel_noise": init.base_vel_noise,
            "random_yaw": init.random_yaw,
            "from_reference": "tracking: the reference's start frame (see `reference`)",
        },
        "terminations": [
            {"name": t.name, "function": t.func.__name__, "params": _plain_params(t.params)}
            for t in task.terminations
        ],
        "time_out": "an episode that reaches max_steps, or a tracking reference's last frame, "
        "ends without failing",
        "randomization": {
            **dataclasses.asdict(task.randomization),
            "friction_geoms": [
                env.physics.model.geom(int(g)).name for g in env.randomizer.writer.contact_geoms
            ],
            "how": "per robot, uniform draws: the sliding friction of friction_geoms (soles, "
            "ground); a payload [kg] added to payload_body's mass, its inertia scaled by the "
            "mass ratio; its centre of mass shifted by com_offset_range_m per axis",
        },
        "pushes": {
            **dataclasses.asdict(task.pushes),
            "how": "per robot a timer drawn from interval_range_s [s]; when it runs out, before "
            "the physics of that policy step, the pelvis's world x and y velocity each change by "
            "a uniform draw within +-velocity_xy_mps (the evaluation's size), and a new timer",
        },
    }


def _plain_params(params: dict[str, Any]) -> dict[str, Any]:
    """A term's parameters as JSON (tuples as lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}


def tracking_reference(env: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
    """The arrays of ``reference.npz`` and the ``reference`` section describing them, from the
    command's :meth:`~rl.envs.components.Command.deployment_reference`; None for a command that
    tracks no reference."""
    found = env.command_gen.deployment_reference()
    if found is None:
        return None
    arrays, section = found
    return arrays, {"file": REFERENCE_FILE, **section,
                    "feedforward": bool(env.task.action_feedforward)}  # fmt: skip


def write_reference(folder: str | Path, env: Any) -> dict[str, Any] | None:
    """Write ``env``'s tracking reference into ``folder`` (:data:`REFERENCE_FILE`); returns the
    ``reference`` section of ``policy.json``, None (nothing written) for a task with none."""
    from optimal_control.files import atomic_save_npz

    found = tracking_reference(env)
    if found is None:
        return None
    arrays, section = found
    path = Path(folder) / REFERENCE_FILE
    atomic_save_npz(path, arrays, compressed=True)
    section["sha256"] = sha256_file(path)
    return section
