"""Play an exported policy bundle in MuJoCo from its folder alone; survival and tracking errors.

This file imports only MuJoCo, onnxruntime, numpy and the standard library: copy it out of the
project and run it beside any bundle::

    python -m a2cf_mb.deploy.run_bundle BUNDLE_FOLDER [--num-envs 8] [--num-steps 0]
    python run_bundle.py BUNDLE_FOLDER --command 0.5 0 0      # a walk: vx [m/s], vy, yaw rate

A bundle folder holds ``policy.onnx``, ``policy.json`` (format ``a2cf-mb-policy/3``) and, for a
tracking policy, ``reference.npz``. From them this script:

* builds the G1 the policy was trained in: the URDF (example-robot-data's, or ``--urdf``; its
  sha256 must be the bundle's) with its geoms removed, then the bundle's colliding geoms (sole
  spheres, link primitives, floor), per joint armature, damping and friction loss, one position
  actuator per joint (PD gains, effort limits) and the simulator options;
* starts each robot as trained: the standing keyframe with the bundle's initial-state noise, or a
  tracking reference's first frame (robot ``i`` tracks clip ``i mod C``), and draws, unless told
  not to, the domain randomisation (friction, payload, centre of mass: a model copy per robot)
  and the pushes it was trained with;
* each 50 Hz step rebuilds the observation term by term from the bundle's layout (with its
  training noise unless ``--no-noise``), keeps the history, runs the ONNX policy and holds the
  joint targets over ``decimation`` physics steps;
* ends an episode on the bundle's terminations (a fall) or its time-out (the length cap, a
  reference's last frame), and scores it: survival, and the task's errors (tracking: joints,
  pelvis, tracked links; walk: velocity).

What it does not do: terrain (the floor only), and commands beyond a constant velocity (or a
script of them) and the gait clock.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import json
import math
import os
import re
import site
import sys
import sysconfig
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import onnxruntime as ort

SUPPORTED_FORMATS = ("a2cf-mb-policy/3",)
"""The ``policy.json`` layouts this script reads."""
URDF_DIR = Path("cmeel.prefix/share/example-robot-data/robots/g1_description/urdf")
"""Where example-robot-data installs the G1 URDF, under a site-packages folder."""
URDF_DIR_ENV = "A2CF_G1_DESCRIPTION_DIR"
"""An environment variable naming a g1_description folder (``urdf/`` inside) to use instead."""


GEOM_FIELDS = {"size": list, "pos": list, "quat": list, "friction": list, "solref": list,
               "solimp": list, "contype": int, "conaffinity": int, "condim": int, "priority": int,
               "margin": float, "gap": float, "solmix": float}  # fmt: skip
"""The fields of a bundle geom and their types."""


class BundleError(ValueError):
    """The bundle folder cannot be played: what is missing or wrong, and what to do."""


# ----------------------------------------------------------------------------------- the bundle
def load_bundle(folder: str | Path) -> dict[str, Any]:
    """``policy.json`` of ``folder`` with its reference arrays under ``"reference_arrays"``."""
    folder = Path(folder)
    path = folder / "policy.json"
    if not path.is_file():
        raise BundleError(f"{folder} has no policy.json: give the folder of an exported policy")
    try:
        bundle = json.loads(path.read_text())
    except ValueError as err:
        raise BundleError(f"{path} is not valid JSON ({err}): export the policy again") from err
    if bundle.get("format") not in SUPPORTED_FORMATS or "model" not in bundle:
        raise BundleError(
            f"{path} has format {bundle.get('format')!r} without the model facts this runner "
            f"needs ({', '.join(SUPPORTED_FORMATS)}): export the policy again with this version"
        )
    if not (folder / bundle["onnx"]).is_file():
        raise BundleError(f"{folder / bundle['onnx']} not found: the bundle is incomplete")
    section = bundle.get("reference")
    if section is not None:
        ref_path = folder / section["file"]
        if not ref_path.is_file():
            raise BundleError(f"{ref_path} not found: a tracking bundle needs its reference")
        with np.load(ref_path) as data:
            bundle["reference_arrays"] = {k: data[k] for k in data.files}
    return bundle


def find_urdf(name: str, urdf: str | Path | None = None) -> Path:
    """The G1 URDF ``name``: ``urdf`` when given, else under ``$A2CF_G1_DESCRIPTION_DIR``, else
    in an installed example-robot-data."""
    if urdf is not None:
        return Path(urdf)
    roots = []
    if os.environ.get(URDF_DIR_ENV):
        roots.append(Path(os.environ[URDF_DIR_ENV]) / "urdf")
    sites = [sysconfig.get_paths()[k] for k in ("purelib", "platlib")]
    sites += list(getattr(site, "getsitepackages", list)()) + [site.getusersitepackages()]
    sites += [p for p in sys.path if p.endswith("site-packages")]
    roots += [Path(s) / URDF_DIR for s in sites]
    for root in roots:
        if (root / name).is_file():
            return root / name
    raise BundleError(
        f"the G1 URDF {name} was not found (searched {', '.join(map(str, roots))}): "
        "`pip install example-robot-data`, or pass --urdf PATH"
    )


def build_model(bundle: dict[str, Any], urdf: str | Path | None = None) -> mujoco.MjModel:
    """The MuJoCo G1 of the bundle's ``model`` facts, from the URDF (see the module docstring)."""
    facts = bundle["model"]
    path = find_urdf(facts["urdf"], urdf)
    text = path.read_text()
    if hashlib.sha256(path.read_bytes()).hexdigest() != facts["urdf_sha256"]:
        raise BundleError(
            f"{path} is not the URDF the policy was trained with (sha256 differs from the "
            "bundle's urdf_sha256): pass the right one with --urdf"
        )
    header = '<mujoco><compiler discardvisual="false" strippath="true"/></mujoco>'
    spec = mujoco.MjSpec.from_string(re.sub(r"(<robot[^>]*>)", r"\1" + header, text, count=1))
    for geom in list(spec.geoms):
        spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    spec.body("pelvis").add_freejoint(name="floating_base")
    for g in facts["geoms"]:
        body = spec.worldbody if g["body"] == "world" else spec.body(g["body"])
        if body is None:
            raise BundleError(f"the bundle's geom on '{g['body']}': no such link in {path}")
        geom = body.add_geom(
            name=g["name"], type=getattr(mujoco.mjtGeom, f"mjGEOM_{g['type'].upper()}")
        )
        for field, kind in GEOM_FIELDS.items():  # one left out is at MuJoCo's default
            if field in g:
                setattr(geom, field, kind(g[field]))
    for joint, extra in zip(bundle["joints"], facts["joints"], strict=True):
        spec_joint = spec.joint(joint["name"])
        spec_joint.armature = extra["armature_kgm2"]
        spec_joint.damping = _first_coefficient(spec_joint.damping, extra["damping_nms"])
        spec_joint.frictionloss = extra["frictionloss_nm"]
        act = spec.add_actuator(
            name=joint["name"], target=joint["name"], trntype=mujoco.mjtTrn.mjTRN_JOINT
        )
        act.set_to_position(kp=joint["kp"], kv=joint["kd"])
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-joint["effort_limit_nm"], joint["effort_limit_nm"]]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    enums = {"integrator": mujoco.mjtIntegrator, "cone": mujoco.mjtCone,
             "solver": mujoco.mjtSolver, "jacobian": mujoco.mjtJacobian}  # fmt: skip
    for field, value in facts["options"].items():
        setattr(spec.option, field, getattr(enums[field], value) if field in enums else value)
    model = spec.compile()
    if abs(model.body_mass.sum() - facts["total_mass_kg"]) > 1e-6:
        raise BundleError(
            f"the G1 built from {path} weighs {model.body_mass.sum():.4f} kg, the trained one "
            f"{facts['total_mass_kg']:.4f} kg: the URDF or this MuJoCo imports it differently"
        )
    return model


def _first_coefficient(current: Any, value: float) -> Any:
    """``value`` in the shape MuJoCo keeps the field in: a scalar, or the first coefficient of a
    vector (MuJoCo 4's polynomial joint damping), the others zero."""
    array = np.atleast_1d(np.asarray(current, dtype=np.float64))
    if array.size == 1:
        return float(value)
    array[:] = 0.0
    array[0] = value
    return array


# ---------------------------------------------------------------------------------- geometry
def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) w x y z."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)  # fmt: skip


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle between orientations (..., 4) w x y z [rad]."""
    dot = np.abs(np.sum(a * b, axis=-1)) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return 2 * np.arccos(np.clip(dot, -1.0, 1.0))


# ------------------------------------------------------------------------------------ the robots
class Robots:
    """N robots (one ``MjData`` each) of one model, with the readings the policy and the judges
    need: joints in the bundle's order, pelvis pose and velocity, tracked links, ground contacts."""

    def __init__(
        self, model: mujoco.MjModel, bundle: dict[str, Any], models: list[mujoco.MjModel]
    ) -> None:
        """Robots of ``model`` (names, sizes), robot ``i`` stepped with ``models[i]``."""
        self.model, self.models = model, models
        self.datas = [mujoco.MjData(m) for m in models]
        names = [j["name"] for j in bundle["joints"]]
        self.qadr = np.array([model.joint(n).qposadr[0] for n in names])
        self.dadr = np.array([model.joint(n).dofadr[0] for n in names])
        self.act = np.array([model.actuator(n).id for n in names])
        self.contact_bodies = list(bundle["model"]["contact_bodies"])
        ref = bundle.get("reference")
        self.bodies = [model.body(b).id for b in ref["bodies"]] if ref else []

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Start every robot from ``qpos`` (N, nq) and ``qvel`` (N, nv)."""
        for model, data, q, v in zip(self.models, self.datas, qpos, qvel, strict=True):
            mujoco.mj_resetData(model, data)
            data.qpos[:], data.qvel[:] = q, v
            mujoco.mj_forward(model, data)

    def step(self, targets_rad: np.ndarray, active: np.ndarray, decimation: int) -> None:
        """Hold joint targets (N, 29) [rad] over ``decimation`` physics steps (active robots)."""
        for i, data in enumerate(self.datas):
            if active[i]:
                data.ctrl[self.act] = targets_rad[i]
                for _ in range(decimation):
                    mujoco.mj_step(self.models[i], data)

    def readings(self) -> dict[str, np.ndarray]:
        """Per robot: pelvis position, quaternion, linear velocity (world) and angular velocity
        (pelvis frame), joints, and the tracked links' world poses (N, K, 3 | 4)."""
        d = self.datas
        qpos = np.stack([x.qpos for x in d])
        qvel = np.stack([x.qvel for x in d])
        out = {
            "base_pos_w": qpos[:, :3], "base_quat_w": qpos[:, 3:7], "base_lin_vel_w": qvel[:, :3],
            "base_ang_vel_b": qvel[:, 3:6], "joint_pos_rad": qpos[:, self.qadr],
            "joint_vel_rps": qvel[:, self.dadr],
        }  # fmt: skip
        out["rot_wb"] = quat_to_mat(out["base_quat_w"])
        if self.bodies:  # the kinematics of the last physics step's start, as training's sensors
            out["body_pos_w"] = np.stack([x.xpos[self.bodies] for x in d])
            out["body_quat_w"] = np.stack([x.xquat[self.bodies] for x in d])
        return out

    def on_ground(self, bodies: list[str]) -> np.ndarray:
        """(N,) bool: any of ``bodies`` (all the contact bodies when empty) touches something."""
        ids = {self.model.body(b).id for b in (bodies or self.contact_bodies)}
        out = np.zeros(len(self.datas), dtype=bool)
        for i, data in enumerate(self.datas):
            for c in data.contact[: data.ncon]:
                touched = {self.model.geom_bodyid[c.geom1], self.model.geom_bodyid[c.geom2]}
                if touched & ids:
                    out[i] = True
                    break
        return out


def randomized_models(model: mujoco.MjModel, bundle: dict[str, Any], num_envs: int, rng):
    """One copy of ``model`` per robot with its own draw of the bundle's domain randomisation
    (``episode.randomization``: friction, payload, centre-of-mass offset); ``model`` itself for
    every robot when the policy was trained without."""
    cfg = bundle["episode"]["randomization"]
    if not cfg["enabled"]:
        return [model] * num_envs
    if "friction_geoms" not in cfg:
        raise BundleError(
            "the bundle's episode.randomization does not name its friction_geoms: export it "
            "again, or play it on the nominal model (--no-randomize)"
        )
    geoms = [model.geom(name).id for name in cfg["friction_geoms"]]
    body = model.body(cfg["payload_body"]).id
    models = []
    for _ in range(num_envs):
        own = copy.copy(model)
        own.geom_friction[geoms, 0] = rng.uniform(*cfg["friction_range"])
        mass = model.body_mass[body] + rng.uniform(*cfg["payload_mass_range_kg"])
        own.body_mass[body] = mass
        own.body_inertia[body] = model.body_inertia[body] * (mass / model.body_mass[body])
        own.body_ipos[body] = model.body_ipos[body] + rng.uniform(*cfg["com_offset_range_m"], 3)
        models.append(own)
    return models


class Pushes:
    """The bundle's pushes (``episode.pushes``): per robot a timer; when it runs out, a uniform
    kick of the pelvis's world x and y velocity within +-``velocity_xy_mps``, a new timer."""

    def __init__(self, bundle: dict[str, Any], num_envs: int, dt_s: float, rng) -> None:
        self.cfg, self.dt_s, self.rng = bundle["episode"]["pushes"], dt_s, rng
        self.timer_s = self._interval(num_envs)

    def _interval(self, num: int) -> np.ndarray:
        return self.rng.uniform(*self.cfg["interval_range_s"], num)

    def apply(self, robots: Robots) -> None:
        """Count one policy step down; kick the robots whose timer ran out."""
        if not self.cfg["enabled"]:
            return
        self.timer_s -= self.dt_s
        due = np.flatnonzero(self.timer_s <= 0)
        v = self.cfg["velocity_xy_mps"]
        for i in due:
            robots.datas[i].qvel[0:2] += self.rng.uniform(-v, v, 2)
        self.timer_s[due] = self._interval(due.size)


# ------------------------------------------------------------------------------------ the command
class Command:
    """The task command the policy reads, built from the bundle's ``parts``: a tracking
    reference's frame (``reference.npz``), or a constant velocity with the gait clock."""

    def __init__(self, bundle: dict[str, Any], num_envs: int, velocity: tuple[float, ...]) -> None:
        term = next((t for t in bundle["observation"]["terms"] if t["name"] == "command"), None)
        self.parts = term["parts"] if term else []
        self.first = term["columns"][0] if term else 0
        self.width = term["columns"][1] - self.first if term else 0
        self.dt_s = 1.0 / bundle["control"]["policy_rate_hz"]
        self.velocity = np.asarray(velocity, dtype=np.float64)
        self.ref = bundle.get("reference_arrays")
        known = {"joint_pos_ref", "joint_vel_ref", "anchor_pos_b", "anchor_rot_b", "lin_vel_x",
                 "lin_vel_y", "ang_vel_z", "gait_clock"}  # fmt: skip
        unknown = [p["name"] for p in self.parts if p["name"] not in known]
        if unknown:
            raise BundleError(f"this runner cannot produce the command parts {unknown}")
        if self.ref is not None:
            section = bundle["reference"]
            c = len(self.ref["clip_start"])
            clip = np.arange(num_envs) % c
            self.start = self.ref["clip_start"][clip]
            self.last = self.start + self.ref["clip_length"][clip] - 1
            self.shift_m = self.ref["floor_shift_m"][self.start]
            self.anchor = section["bodies"].index(section["anchor_body"])
            self.pelvis = section["bodies"].index("pelvis")
            self.end_effectors = [
                section["bodies"].index(b) for b in section["end_effector_bodies"]
            ]
        self.steps = 0

    def frame(self) -> np.ndarray:
        """(N,) the reference frame the current step targets (held at each clip's last)."""
        return np.minimum(self.start + self.steps + 1, self.last)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Each robot's reference start frame, on the floor: qpos (N, 36), qvel (N, 35)."""
        qpos = self.ref["qpos"][self.start].copy()
        qpos[:, 2] -= self.shift_m
        return qpos, self.ref["qvel"][self.start].copy()

    def reference_qpos(self, env: int) -> np.ndarray:
        """Robot ``env``'s reference pose (nq,) of the current step's frame, on the floor."""
        qpos = self.ref["qpos"][self.frame()[env]].astype(np.float64)
        qpos[2] -= self.shift_m[env]
        return qpos

    def targets(self) -> dict[str, np.ndarray]:
        """The reference frame the current step targets, its links lowered by the floor shift."""
        n = self.frame()
        pos = self.ref["body_pos_w"][n].astype(np.float64)
        pos[..., 2] -= self.shift_m[:, None]
        return {
            "frame": n, "joint_pos_rad": self.ref["joint_pos_rad"][n].astype(np.float64),
            "joint_vel_rps": self.ref["joint_vel_rps"][n].astype(np.float64),
            "body_pos_w": pos, "body_quat_w": self.ref["body_quat_w"][n].astype(np.float64),
            "joint_torque_nm": self.ref["joint_torque_nm"][n].astype(np.float64),
            "phase": self.ref["phase"][n],
        }  # fmt: skip

    def columns(self, r: dict[str, np.ndarray]) -> np.ndarray:
        """The command (N, C) of the current step, from the robots' readings ``r``."""
        n = r["joint_pos_rad"].shape[0]
        out = np.zeros((n, self.width))
        t = self.targets() if self.ref is not None else None
        for part in self.parts:
            a, b = (c - self.first for c in part["columns"])
            name = part["name"]
            if name in ("joint_pos_ref", "joint_vel_ref"):
                out[:, a:b] = t["joint_pos_rad" if name == "joint_pos_ref" else "joint_vel_rps"]
            elif name in ("anchor_pos_b", "anchor_rot_b"):
                rot_wa = quat_to_mat(r["body_quat_w"][:, self.anchor])
                if name == "anchor_pos_b":
                    delta = t["body_pos_w"][:, self.anchor] - r["body_pos_w"][:, self.anchor]
                    out[:, a:b] = np.einsum("nji,nj->ni", rot_wa, delta)
                else:  # first two columns of R_robot^T R_ref, column-major
                    rel = np.swapaxes(rot_wa, 1, 2) @ quat_to_mat(t["body_quat_w"][:, self.anchor])
                    out[:, a:b] = np.concatenate([rel[:, :, 0], rel[:, :, 1]], axis=1)
            elif name in ("lin_vel_x", "lin_vel_y", "ang_vel_z"):
                out[:, a] = self.velocity[["lin_vel_x", "lin_vel_y", "ang_vel_z"].index(name)]
            elif name == "gait_clock":
                period = float(re.search(r"/ ([0-9.eE+-]+) s", part["compute"]).group(1))
                angle = 2 * math.pi * (self.steps * self.dt_s / period % 1.0)
                out[:, a], out[:, a + 1] = math.sin(angle), math.cos(angle)
        return out


# ----------------------------------------------------------------------------- the observation
def observation(bundle: dict[str, Any], r: dict[str, np.ndarray], last_action, command):
    """The policy observation (N, P) from the robots' readings, term by term as the bundle says."""
    rot_bw = np.swapaxes(r["rot_wb"], 1, 2)
    default = np.array([j["default_pos_rad"] for j in bundle["joints"]])
    signals = {
        "base_ang_vel": r["base_ang_vel_b"],
        "projected_gravity": rot_bw @ np.array([0.0, 0.0, -1.0]),
        "joint_pos": r["joint_pos_rad"] - default,
        "joint_vel": r["joint_vel_rps"],
        "last_action": last_action,
        "command": command,
        "base_lin_vel": np.einsum("nij,nj->ni", rot_bw, r["base_lin_vel_w"]),
    }
    obs = np.zeros((r["joint_pos_rad"].shape[0], bundle["observation"]["width"]))
    for term in bundle["observation"]["terms"]:
        if term["name"] not in signals:
            raise BundleError(f"this runner cannot compute observation term '{term['name']}'")
        a, b = term["columns"]
        obs[:, a:b] = term["scale"] * signals[term["name"]]
    return obs


def noise_amplitude(bundle: dict[str, Any]) -> np.ndarray:
    """Half-widths (P,) of the uniform noise the policy was trained with, per column."""
    out = np.zeros(bundle["observation"]["width"])
    if bundle["observation"].get("noisy", False):
        for term in bundle["observation"]["terms"]:
            a, b = term["columns"]
            out[a:b] = term["training_noise"]
    return out


# ----------------------------------------------------------------------------------- the judges
def failures(bundle: dict[str, Any], robots: Robots, command: Command, r, t) -> np.ndarray:
    """(N,) bool: any of the bundle's terminations after this step (``t``: the step's targets)."""
    n = r["base_pos_w"].shape[0]
    failed = np.zeros(n, dtype=bool)
    for term in bundle["episode"]["terminations"]:
        fn, p = term["function"], term["params"]
        free = np.isin(t["phase"], p.get("free_phases", [])) if t is not None else False
        if fn == "base_too_low":
            hit = r["base_pos_w"][:, 2] < p["min_height_m"]
        elif fn == "base_tilted":
            hit = r["rot_wb"][:, 2, 2] < math.cos(p["max_tilt_rad"])
        elif fn == "link_on_ground":
            hit = robots.on_ground(p.get("bodies", []))
        elif fn == "anchor_height_drift":
            a = command.anchor
            hit = np.abs(r["body_pos_w"][:, a, 2] - t["body_pos_w"][:, a, 2]) > p["max_m"]
        elif fn == "anchor_tilt_drift":
            a = command.anchor
            up = quat_to_mat(r["body_quat_w"][:, a])[:, :, 2]
            up_ref = quat_to_mat(t["body_quat_w"][:, a])[:, :, 2]
            angle = np.arccos(np.clip(np.sum(up * up_ref, axis=-1), -1.0, 1.0))
            hit = (angle > p["max_rad"]) & ~free
        elif fn == "end_effector_height_drift":
            idx = command.end_effectors
            err = np.abs(r["body_pos_w"][:, idx, 2] - t["body_pos_w"][:, idx, 2])
            hit = (err > p["max_m"]).any(-1) & ~free
        else:
            raise BundleError(f"this runner does not know the termination '{fn}' ({term['name']})")
        failed |= hit
    return failed


def tracking_errors(command: Command, r, t) -> dict[str, np.ndarray]:
    """Per robot (N,): mean joint error [rad], pelvis position error [m] and orientation error
    [rad], tracked links' world (MPKPE) and anchor-relative position errors [m]."""
    a, p = command.anchor, command.pelvis
    rel = r["body_pos_w"] - r["body_pos_w"][:, a : a + 1]
    rel_ref = t["body_pos_w"] - t["body_pos_w"][:, a : a + 1]
    return {
        "joint_error_rad": np.abs(r["joint_pos_rad"] - t["joint_pos_rad"]).mean(-1),
        "pelvis_pos_error_m": np.linalg.norm(
            r["body_pos_w"][:, p] - t["body_pos_w"][:, p], axis=-1
        ),
        "pelvis_rot_error_rad": quat_angle(r["body_quat_w"][:, p], t["body_quat_w"][:, p]),
        "body_pos_error_m": np.linalg.norm(r["body_pos_w"] - t["body_pos_w"], axis=-1).mean(-1),
        "body_rel_error_m": np.linalg.norm(rel - rel_ref, axis=-1).mean(-1),
    }


def velocity_errors(command: Command, r) -> dict[str, np.ndarray]:
    """Per robot (N,): planar velocity error [m/s] and yaw-rate error [rad/s] (pelvis frame)."""
    v_b = np.einsum("nji,nj->ni", r["rot_wb"], r["base_lin_vel_w"])
    return {
        "lin_vel_error_mps": np.linalg.norm(v_b[:, :2] - command.velocity[:2], axis=-1),
        "yaw_rate_error_rps": np.abs(r["base_ang_vel_b"][:, 2] - command.velocity[2]),
    }


# ------------------------------------------------------------------------------------ the rollout
def initial_state(bundle: dict[str, Any], command: Command, num_envs: int, rng, noise: bool):
    """Start states (N, 36), (N, 35): a reference's start frame, or the standing keyframe with
    the bundle's initial-state noise (``noise`` off: none)."""
    if command.ref is not None:
        return command.initial_state()
    init = bundle["episode"]["initial_state"]
    qpos = np.tile(np.asarray(bundle["model"]["stand_qpos"]), (num_envs, 1))
    qvel = np.zeros((num_envs, qpos.shape[1] - 1))
    if noise:
        qpos[:, 7:] += (
            rng.uniform(-1, 1, (num_envs, qpos.shape[1] - 7)) * init["joint_pos_noise_rad"]
        )
        if init["random_yaw"]:
            yaw = rng.uniform(-math.pi, math.pi, num_envs)
            qpos[:, 3:7] = np.stack(
                [np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1
            )  # the keyframe is upright: the heading alone is its orientation
        qvel[:, :6] = rng.uniform(-1, 1, (num_envs, 6)) * init["base_vel_noise"]
    return qpos, qvel


def run_bundle(
    folder: str | Path,
    num_envs: int = 8,
    num_steps: int = 0,
    seed: int = 0,
    noise: bool = True,
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
    urdf: str | Path | None = None,
    script: tuple[tuple[float, tuple[float, float, float]], ...] = (),
    on_step: Callable[[np.ndarray, np.ndarray | None, np.ndarray], None] | None = None,
    command_at: Callable[[float], Sequence[float]] | None = None,
    randomize: bool = True,
    pushes: bool = True,
) -> dict[str, Any]:
    """Roll the bundle's policy out on ``num_envs`` robots, one episode each, for ``num_steps``
    policy steps (0: the episode's length cap); survival, episode length and the task's errors
    (frame-weighted means over the steps each robot was still in its episode after).

    ``noise``: the observation noise and initial-state noise the policy was trained with;
    ``randomize``, ``pushes``: its domain randomisation and pushes (where it was trained with
    them);
    ``velocity``: (vx [m/s], vy [m/s], yaw rate [rad/s]) for a policy that reads one (walk);
    ``script``: ((duration [s], velocity), ...) in place of it, by episode time (the last held);
    ``command_at(t)``: in place of both, the velocity at episode time t [s] (a live command, e.g.
    the keyboard's in a viewer);
    ``on_step(qpos, reference_qpos, velocity)`` sees robot 0 after each of its steps (a video's
    frames): its MuJoCo qpos (nq,), its reference pose (nq,) for a tracking policy (else None)
    and the velocity command (3,)."""
    folder = Path(folder)
    bundle = load_bundle(folder)
    model = build_model(bundle, urdf)
    session = ort.InferenceSession(str(folder / bundle["onnx"]), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(seed)
    command = Command(bundle, num_envs, velocity)
    models = randomized_models(model, bundle, num_envs, rng) if randomize else [model] * num_envs
    robots = Robots(model, bundle, models)
    robots.set_state(*initial_state(bundle, command, num_envs, rng, noise))
    control = bundle["control"]
    decimation = round(1.0 / control["policy_rate_hz"] / model.opt.timestep)
    joints = bundle["joints"]
    kp, kd = (np.array([j[k] for j in joints]) for k in ("kp", "kd"))
    default = np.array([j["default_pos_rad"] for j in joints])
    scale = np.array([j["action_scale_rad"] for j in joints])
    clip = bundle["clip_actions"]
    amplitude = noise_amplitude(bundle) if noise else np.zeros(bundle["observation"]["width"])
    h = bundle["observation"]["history_length"]
    max_steps = bundle["episode"]["max_steps"]
    num_steps = num_steps or max_steps
    active = np.ones(num_envs, dtype=bool)
    fell = np.zeros(num_envs, dtype=bool)
    lengths = np.zeros(num_envs)
    sums: dict[str, np.ndarray] = {}
    scored = np.zeros(num_envs)
    last_action = np.zeros((num_envs, len(joints)))
    history = None
    kicks = Pushes(bundle, num_envs, decimation * model.opt.timestep, rng) if pushes else None
    ends_s = np.cumsum([d for d, _ in script]) if script else None
    for k in range(num_steps):
        command.steps = k
        if command_at is not None:
            command.velocity = np.asarray(command_at(k * command.dt_s), dtype=np.float64)
        elif script:
            segment = min(
                int(np.searchsorted(ends_s, k * command.dt_s, side="right")), len(script) - 1
            )
            command.velocity = np.asarray(script[segment][1], dtype=np.float64)
        r = robots.readings()
        obs = observation(bundle, r, last_action, command.columns(r))
        obs = obs + rng.uniform(-1, 1, obs.shape) * amplitude if amplitude.any() else obs
        obs = obs.astype(np.float32)
        history = [obs] * h if history is None else [*history[1:], obs]
        (action,) = session.run(None, {"obs": obs, "history": np.concatenate(history, axis=1)})
        action = np.clip(action.astype(np.float64), -clip, clip)
        t = command.targets() if command.ref is not None else None
        base = default if t is None else t["joint_pos_rad"]
        if t is not None and bundle["reference"].get("feedforward"):
            base = base + kd / kp * t["joint_vel_rps"] + t["joint_torque_nm"] / kp
        if kicks is not None:
            kicks.apply(robots)
        robots.step(base + scale * action, active, decimation)
        if on_step is not None and active[0]:
            ghost = command.reference_qpos(0) if command.ref is not None else None
            on_step(robots.datas[0].qpos.copy(), ghost, command.velocity.copy())
        r = robots.readings()
        failed = failures(bundle, robots, command, r, t)
        ends = np.full(num_envs, k + 1 >= max_steps)
        if t is not None:
            ends |= t["frame"] >= command.last
        done = failed | ends
        errors = tracking_errors(command, r, t) if t is not None else {}
        if any(p["name"] == "lin_vel_x" for p in command.parts):
            errors = velocity_errors(command, r)
        keep = active & ~done  # the step that ends an episode is not scored (as training's judge)
        for key, value in errors.items():
            sums[key] = sums.get(key, np.zeros(num_envs)) + np.where(keep, value, 0.0)
        scored += keep
        lengths += active
        fell |= active & failed
        active &= ~done
        last_action = action
        if not active.any():
            break
    frames = scored.sum()
    metrics = {key: float(value.sum() / frames) if frames else float("nan")
               for key, value in sums.items()}  # fmt: skip
    return {
        "bundle": str(folder),
        "task": bundle["task"],
        "runner": "a2cf_mb/deploy/run_bundle.py: the bundle's G1 in MuJoCo, flat floor",
        "randomized": bool(randomize and bundle["episode"]["randomization"]["enabled"]),
        "pushes": bool(kicks is not None and bundle["episode"]["pushes"]["enabled"]),
        "num_envs": num_envs,
        "num_steps": num_steps,
        "observation_noise": bool(amplitude.any()),
        "survival_fraction": float((~fell).mean()),
        "mean_episode_length_steps": float(lengths.mean()),
        **({"task_metrics": {**metrics, "frames_scored": int(frames)}} if metrics else {}),
    }


def main(argv: list[str] | None = None) -> int:
    """Command line: play a bundle folder, print the result as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", help="bundle folder: policy.onnx, policy.json (reference.npz)")
    parser.add_argument("--num-envs", type=int, default=8, help="robots, one episode each [-]")
    parser.add_argument("--num-steps", type=int, default=0, help="policy steps; 0: the cap [-]")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise draws [-]")
    parser.add_argument("--no-noise", action="store_true", help="no observation / start noise")
    parser.add_argument("--no-randomize", action="store_true", help="the nominal model only")
    parser.add_argument("--no-pushes", action="store_true", help="no pushes")
    parser.add_argument("--command", type=float, nargs=3, default=(0.0, 0.0, 0.0),
                        metavar=("VX", "VY", "WZ"),
                        help="a walk's velocity command: vx, vy [m/s], yaw rate [rad/s]")  # fmt: skip
    parser.add_argument("--urdf", default=None, help="the G1 URDF (default: example-robot-data's)")
    args = parser.parse_args(argv)
    try:
        result = run_bundle(
            args.folder, args.num_envs, args.num_steps, args.seed, not args.no_noise,
            tuple(args.command), args.urdf, randomize=not args.no_randomize,
            pushes=not args.no_pushes,
        )  # fmt: skip
    except BundleError as err:
        print(f"run_bundle: {err}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
