"""Capsules and boxes fitted to the G1's link meshes: contact for a fallen robot without meshes.

The envs step a mesh-free G1 (a compiled model with its meshes is ~56 MB, one copy per env), so
without these only the 8 sole spheres touch the floor: a fallen robot sinks through it, shins do not
catch stair edges. :func:`fit_link_primitives` fits one primitive per URDF collision mesh (plus the
rubber hands, which the URDF has as visuals only); :func:`add_link_primitives` adds them to a
mesh-free ``MjSpec``::

    spec = remove_meshes(build_mujoco_spec(MujocoModelConfig()))
    add_link_primitives(spec, fit_link_primitives())

Fit: our own, from the vertices of each mesh's convex hull (MuJoCo collides a mesh as its hull), in
the body frame. A box is the tightest axis-aligned box in the body frame or in the hull's principal
(PCA) frame; a capsule takes an axis among those six, the exact minimal enclosing circle of the
vertices projected across it as its radius and the shortest half-length that still holds every
vertex. Both enclose every vertex, so a primitive touches whatever the mesh would have touched,
never later (how much earlier, and each fit's volume against the hull's: ``docs/environments.md``).
MuJoCo's own fitting (a primitive geom with ``meshname``) is worse for this: the default fit matches
the mesh's inertia and leaves vertices outside; with ``compiler.fitaabb`` boxes in the inertial
frame enclose all vertices but are larger than ours, and capsules leave vertices outside and fail
to compile ("size 1 must be positive") for the pelvis, logo and wrist meshes, which are not
elongated.

Type: the capsule is taken when its volume is at most :data:`CAPSULE_VOLUME_TOLERANCE` times the
box's (capsules are the cheaper, smoother contact), decided once per left/right pair so that both
sides get the same type. Result: capsules on thighs, elbows and two wrist links, boxes elsewhere.

Contact filter (MuJoCo: geoms A, B collide when ``contype_A & conaffinity_B`` or
``contype_B & conaffinity_A``): floor and terrain contype 1, conaffinity 3; sole spheres 1 / 1;
link primitives contype 2, conaffinity 0. So primitives hit the floor (2 & 3) and nothing on the
robot (2 & 0, 2 & 1), exactly like the URDF collision meshes (and the URDF's shoulder cylinders,
which survive mesh removal) of :mod:`robots.mujoco_model`. Terrain geoms must keep bit 2 in their
conaffinity to be hit by links. For self-collision set ``LinkCollisionConfig.conaffinity = 2``
(MuJoCo filters parent-child pairs).

Known flaw (``docs/environments.md``): the shin (knee link) box's lowest corner sits by the
ankle, below the mesh; in a deep crouch with the shank tilted forward it dips into the floor behind
the heel, a support the mesh (and the robot) does not have. A flip policy trained on it pushes off
that corner and loses it in sim2sim (URDF meshes). ``solve-backflip --shin-clearance`` keeps
references off it.

Mass: the URDF gives every body an explicit inertial (``inertiafromgeom`` auto uses it), and the
primitives are added with density 0, so mass, CoM and inertia do not change.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from functools import lru_cache

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from robots import g1
from robots.mujoco_model import STAND_KEYFRAME, MujocoModelConfig, build_mujoco_spec

CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE
BOX = mujoco.mjtGeom.mjGEOM_BOX

CAPSULE_VOLUME_TOLERANCE = 1.1
"""A capsule is preferred over a box while its volume is at most this multiple of the box's [-]."""

VISUAL_MESHES_FITTED = ("left_rubber_hand", "right_rubber_hand")
"""Visual-only URDF meshes that get a primitive: the hands are what lands first in a fall."""

MERGED_MESHES = {"logo_link": "torso_link_rev_1_0"}
"""Meshes fitted together with another mesh of the same body: the chest logo, a thin curved plate,
lies within 2 mm of the torso box; a primitive of its own would only add a geom."""

FOOT_LINKS = tuple(
    name
    for side in ("left", "right")
    for name in (f"{side}_ankle_pitch_link", f"{side}_ankle_roll_link")
)
"""Links not given primitives by default: the feet (ankle roll), whose contact the 4 sole spheres
per foot model (a box under them would fight them), and the ankle pitch links, 4 cm parts that sit
2.8 cm above the sole between shin and foot."""


@dataclass(frozen=True)
class LinkPrimitive:
    """One collision primitive of a G1 link, placed in the link (body) frame."""

    body: str  # MuJoCo body (URDF link) name
    source_mesh: str  # mesh it was fitted to (merged meshes are listed by the first name)
    geom_type: mujoco.mjtGeom  # mjGEOM_CAPSULE or mjGEOM_BOX
    size_m: tuple[float, float, float]  # capsule (radius, half-length, 0); box half-extents [m]
    pos_m: tuple[float, float, float]  # centre in the body frame [m]
    quat: tuple[float, float, float, float]  # orientation in the body frame, wxyz [-]
    hull_volume_m3: float  # volume of the convex hull of the mesh vertices [m^3]

    @property
    def geom_name(self) -> str:
        """Name of the geom :func:`add_link_primitives` creates."""
        return f"{self.source_mesh}_collision"

    @property
    def volume_m3(self) -> float:
        """Volume of the primitive [m^3]."""
        return _volume_m3(self.geom_type, np.asarray(self.size_m))


@dataclass(frozen=True)
class LinkCollisionConfig:
    """How :func:`add_link_primitives` adds link primitives to a spec."""

    contype: int = 2  # contact type bits: 2 is in the floor's conaffinity (3) [-]
    conaffinity: int = 0  # 0: no contact with other robot geoms [-]
    condim: int = 3  # contact dimension: normal + 2D sliding friction [-]
    group: int = 3  # geom group (3: collision geoms, hidden by default in the viewer) [-]
    skip_bodies: tuple[str, ...] = field(default=FOOT_LINKS)  # bodies given no primitive


def _volume_m3(geom_type: mujoco.mjtGeom, size_m: np.ndarray) -> float:
    if geom_type == BOX:
        return float(8.0 * np.prod(size_m))
    radius, half_length = float(size_m[0]), float(size_m[1])
    return float(np.pi * radius**2 * 2.0 * half_length + 4.0 / 3.0 * np.pi * radius**3)


def _mat_to_quat(rot: np.ndarray) -> tuple[float, float, float, float]:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot, dtype=float).reshape(9))
    return tuple(float(x) for x in quat)


def _min_enclosing_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Exact smallest circle holding 2D points, shape (n, 2) (Welzl, shuffled, expected O(n))."""

    def through_two(a, b):
        centre = 0.5 * (a + b)
        return centre, float(np.linalg.norm(a - centre))

    def through_three(a, b, c):
        d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        if abs(d) < 1e-18:  # collinear: the widest pair spans the circle
            return max(
                (through_two(a, b), through_two(a, c), through_two(b, c)), key=lambda t: t[1]
            )
        sa, sb, sc = a @ a, b @ b, c @ c
        centre = (
            np.array(
                [
                    sa * (b[1] - c[1]) + sb * (c[1] - a[1]) + sc * (a[1] - b[1]),
                    sa * (c[0] - b[0]) + sb * (a[0] - c[0]) + sc * (b[0] - a[0]),
                ]
            )
            / d
        )
        return centre, float(np.linalg.norm(a - centre))

    # The circle is set by the 2D hull's corners (tens of points, not thousands); Python floats.
    pts = points[ConvexHull(points).vertices] if len(points) > 3 else points
    pts = [np.asarray(p) for p in pts[np.random.default_rng(0).permutation(len(pts))].tolist()]

    def outside(p, c, r):
        return float(np.hypot(*(p - c))) > r + 1e-12

    centre, radius = pts[0], 0.0
    for i in range(1, len(pts)):
        if outside(pts[i], centre, radius):
            centre, radius = pts[i], 0.0
            for j in range(i):
                if outside(pts[j], centre, radius):
                    centre, radius = through_two(pts[i], pts[j])
                    for k in range(j):
                        if outside(pts[k], centre, radius):
                            centre, radius = through_three(pts[i], pts[j], pts[k])
    return centre, radius


def _fit_box(
    vertices_m: np.ndarray, frames: list[np.ndarray]
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Smallest box over candidate frames (columns = box axes in the body frame)."""
    best = None
    for rot in frames:
        local = vertices_m @ rot
        lo, hi = local.min(axis=0), local.max(axis=0)
        half = 0.5 * (hi - lo)
        volume = _volume_m3(BOX, half)
        if best is None or volume < best[0]:
            best = (volume, half, rot @ (0.5 * (hi + lo)), rot)
    return best


def _fit_capsule(
    vertices_m: np.ndarray, axes: list[np.ndarray]
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Smallest enclosing capsule over candidate axes (MuJoCo capsules lie along their local z)."""
    best = None
    for axis in axes:
        axis = axis / np.linalg.norm(axis)
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
        u = np.cross(axis, helper)
        u /= np.linalg.norm(u)
        w = np.cross(axis, u)
        across = np.stack([vertices_m @ u, vertices_m @ w], axis=1)
        centre_2d, radius = _min_enclosing_circle(across)
        along = vertices_m @ axis
        # A vertex at distance rho from the axis is inside while |t - c| <= h + sqrt(R^2 - rho^2).
        rho = np.linalg.norm(across - centre_2d, axis=1)
        slack = np.sqrt(np.maximum(radius**2 - rho**2, 0.0))
        lo, hi = np.max(along - slack), np.min(along + slack)
        half_length = max(0.5 * (lo - hi), 0.0)
        size = np.array([radius, half_length, 0.0])
        volume = _volume_m3(CAPSULE, size)
        if best is None or volume < best[0]:
            centre = centre_2d[0] * u + centre_2d[1] * w + 0.5 * (lo + hi) * axis
            best = (volume, size, centre, np.stack([u, w, axis], axis=1))
    return best


def _mesh_vertices_body_m(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """Vertices of a mesh geom in its body frame [m], shape (n, 3)."""
    mesh = model.geom_dataid[geom]
    start = model.mesh_vertadr[mesh]
    vertices = model.mesh_vert[start : start + model.mesh_vertnum[mesh]].astype(float)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[geom])
    return vertices @ rot.reshape(3, 3).T + model.geom_pos[geom]


def _fit_sources(model: mujoco.MjModel) -> dict[tuple[str, str], np.ndarray]:
    """(body, mesh) -> body-frame vertices of every mesh to fit, merged meshes joined."""
    sources: dict[tuple[str, str], np.ndarray] = {}
    merged: dict[tuple[str, str], np.ndarray] = {}
    for geom in range(model.ngeom):
        if model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        mesh = model.mesh(model.geom_dataid[geom]).name
        collision = model.geom_contype[geom] != 0 or model.geom_conaffinity[geom] != 0
        if not (collision or mesh in VISUAL_MESHES_FITTED):
            continue
        body = model.body(model.geom_bodyid[geom]).name
        target = merged if mesh in MERGED_MESHES else sources
        target[(body, MERGED_MESHES.get(mesh, mesh))] = _mesh_vertices_body_m(model, geom)
    for key, vertices in merged.items():
        if key not in sources:
            raise ValueError(f"Mesh merged into '{key[1]}' of body '{key[0]}', which has none.")
        sources[key] = np.vstack([sources[key], vertices])
    if not sources:
        raise ValueError("The model has no collision meshes to fit; build it with its meshes.")
    return sources


def _pair_key(name: str) -> str:
    for side in ("left_", "right_"):
        if name.startswith(side):
            return name[len(side) :]
    return name


def fit_primitives(model: mujoco.MjModel) -> tuple[LinkPrimitive, ...]:
    """Fit a capsule or box to every collision mesh (and the hands) of a compiled G1 with meshes.

    ``model`` is a G1 compiled from :func:`robots.mujoco_model.build_mujoco_spec` with its meshes
    (collision meshes are the mesh geoms with a nonzero contype or conaffinity). Each primitive
    encloses every vertex of its mesh. Prefer the cached :func:`fit_link_primitives`.
    """
    fits = {}
    for (body, mesh), vertices in _fit_sources(model).items():
        hull = ConvexHull(vertices)
        points = vertices[hull.vertices]
        _, eigvecs = np.linalg.eigh(np.cov((points - points.mean(axis=0)).T))
        if np.linalg.det(eigvecs) < 0:
            eigvecs[:, 0] *= -1.0
        frames = [np.eye(3), eigvecs]
        axes = [*np.eye(3), *eigvecs.T]
        fits[(body, mesh)] = (hull.volume, _fit_box(points, frames), _fit_capsule(points, axes))
    # Type per left/right pair (summed volumes), so that mirrored links get the same primitive.
    pair_volumes: dict[str, np.ndarray] = {}
    for (_, mesh), (_, box, capsule) in fits.items():
        pair_volumes.setdefault(_pair_key(mesh), np.zeros(2))
        pair_volumes[_pair_key(mesh)] += (box[0], capsule[0])
    primitives = []
    for (body, mesh), (hull_volume, box, capsule) in fits.items():
        box_volume, capsule_volume = pair_volumes[_pair_key(mesh)]
        use_capsule = capsule_volume <= CAPSULE_VOLUME_TOLERANCE * box_volume
        _, size, centre, rot = capsule if use_capsule else box
        primitives.append(
            LinkPrimitive(
                body=body,
                source_mesh=mesh,
                geom_type=CAPSULE if use_capsule else BOX,
                size_m=tuple(float(x) for x in size),
                pos_m=tuple(float(x) for x in centre),
                quat=_mat_to_quat(rot),
                hull_volume_m3=float(hull_volume),
            )
        )
    return tuple(primitives)


@lru_cache(maxsize=1)
def fit_link_primitives() -> tuple[LinkPrimitive, ...]:
    """The G1's link primitives, fitted once per process (about 1 s) to a G1 built with meshes.

    Independent of any caller's spec: it builds and compiles its own
    ``build_mujoco_spec(MujocoModelConfig())`` with meshes, so call it before or after deleting
    meshes from yours. Returns one :class:`LinkPrimitive` per fitted mesh, feet included (
    :func:`add_link_primitives` skips them by default).
    """
    return fit_primitives(build_mujoco_spec(MujocoModelConfig()).compile())


def remove_meshes(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Delete every mesh geom and mesh asset of ``spec`` in place (URDF inertials stay); returns it."""
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    return spec


def _sole_friction(spec: mujoco.MjSpec) -> list[float]:
    """Friction (sliding, torsional, rolling) of the sole spheres: the robot's contact material."""
    name = f"{g1.SOLE_FRAMES[0]}_0"
    sole = spec.geom(name)
    if sole is None:
        raise ValueError(
            f"Sole sphere '{name}' not in the spec: add_link_primitives copies the sole friction; "
            "pass a spec from robots.mujoco_model.build_mujoco_spec()."
        )
    return list(sole.friction)


def add_link_primitives(
    spec: mujoco.MjSpec,
    primitives: tuple[LinkPrimitive, ...],
    cfg: LinkCollisionConfig = LinkCollisionConfig(),
) -> mujoco.MjSpec:
    """Add link primitives to ``spec`` (in place) as massless geoms that collide with the floor only.

    ``spec`` is a G1 spec from :func:`robots.mujoco_model.build_mujoco_spec`, usually after
    :func:`remove_meshes`; ``primitives`` usually :func:`fit_link_primitives`. Bodies in
    ``cfg.skip_bodies`` (the feet) are skipped. Geoms are named ``LinkPrimitive.geom_name``, take the
    sole spheres' friction and density 0 (the URDF inertials stay). Returns ``spec``.
    """
    friction = _sole_friction(spec)
    missing = sorted({p.body for p in primitives if spec.body(p.body) is None})
    if missing:
        raise ValueError(
            f"Bodies {missing} of the primitives are not in the spec (not a G1 spec?)."
        )
    for primitive in primitives:
        if primitive.body in cfg.skip_bodies:
            continue
        if spec.geom(primitive.geom_name) is not None:
            raise ValueError(
                f"Geom '{primitive.geom_name}' already exists: add_link_primitives was called twice."
            )
        spec.body(primitive.body).add_geom(
            name=primitive.geom_name,
            type=primitive.geom_type,
            size=list(primitive.size_m),
            pos=list(primitive.pos_m),
            quat=list(primitive.quat),
            contype=cfg.contype,
            conaffinity=cfg.conaffinity,
            condim=cfg.condim,
            friction=friction,
            density=0.0,
            group=cfg.group,
            rgba=[0.2, 0.6, 0.9, 0.4],
        )
    return spec


def build_collision_model(
    cfg: MujocoModelConfig = MujocoModelConfig(), link_collisions: bool = True
) -> mujoco.MjModel:
    """Compile the mesh-free G1: sole spheres only, or with the link primitives (a fresh model)."""
    spec = remove_meshes(build_mujoco_spec(cfg))
    if link_collisions:
        add_link_primitives(spec, fit_link_primitives())
    return spec.compile()


@dataclass(frozen=True)
class StepRateConfig:
    """Options of :func:`measure_step_rates`."""

    steps: int = 2000  # physics steps per timing [-]
    repeats: int = 4  # timings per model and scenario, interleaved between the models [-]
    target_noise_rad: float = 0.5  # amplitude of the uniform random joint targets [rad]
    target_period_s: float = 0.2  # random targets are redrawn this often [s]
    stand_episode_s: float = 1.0  # "stand" resets this often: open loop it topples at 1.2 s [s]
    random_episode_s: float = 4.0  # "random" resets this often: it falls at ~1 s, then lies [s]
    seed: int = 0  # random generator seed [-]


def _rollout(
    model: mujoco.MjModel, scenario: str, cfg: StepRateConfig, seed: int, count_contacts: bool
) -> float:
    """Steps/s of ``mj_step`` on one thread [1/s], or (count_contacts) mean contacts per step.

    Episodes start from the standing keyframe; "stand" holds the standing targets, "random" adds
    uniform noise of ``cfg.target_noise_rad`` redrawn every ``cfg.target_period_s``.
    """
    data = mujoco.MjData(model)
    key = model.key(STAND_KEYFRAME).id
    mujoco.mj_resetDataKeyframe(model, data, key)
    dt_s = model.opt.timestep
    redraw = max(1, round(cfg.target_period_s / dt_s))
    episode_s = cfg.random_episode_s if scenario == "random" else cfg.stand_episode_s
    episode = max(1, round(episode_s / dt_s))
    # Targets drawn up front: both models see the same ones and the timing excludes numpy.
    noise = np.random.default_rng(seed).uniform(-1.0, 1.0, (cfg.steps // redraw + 1, model.nu))
    amplitude_rad = cfg.target_noise_rad if scenario == "random" else 0.0
    targets = data.ctrl + amplitude_rad * noise
    contacts = 0
    start = time.perf_counter()
    for step in range(cfg.steps):
        if step % episode == 0 and step > 0:
            mujoco.mj_resetDataKeyframe(model, data, key)
        if step % redraw == 0:
            data.ctrl[:] = targets[step // redraw]
        mujoco.mj_step(model, data)
        if count_contacts:
            contacts += data.ncon
    elapsed_s = time.perf_counter() - start
    return contacts / cfg.steps if count_contacts else cfg.steps / elapsed_s


def measure_step_rates(cfg: StepRateConfig = StepRateConfig()) -> dict[str, dict[str, float]]:
    """Steps/s of the sole-only vs the link-primitive G1, standing and under random joint targets.

    "stand": 1 s episodes upright (only soles touch). "random": 4 s episodes in which the G1
    stumbles, falls and lies: the sole-only model sinks through the floor, the primitive one lies
    on it with more contacts, so this is the costliest case for the primitives.

    Timings alternate between the two models ``cfg.repeats`` times; the median of each is
    reported. Machines are noisy: read the ratio, never assert it. Returns
    ``{scenario: {"soles_steps_per_s", "links_steps_per_s", "ratio", "soles_ncon", "links_ncon"}}``
    (ratio = links / soles; ncon = mean contacts per step) and ``{"memory": {...}}``: per model
    (soles, links, and the G1 with meshes for scale) ``<name>_model_bytes`` (``MjModel.nbuffer``),
    ``<name>_data_bytes`` (``MjData`` buffer + arena) [bytes] and ``<name>_ngeom``.
    """
    models = {
        "soles": build_collision_model(link_collisions=False),
        "links": build_collision_model(link_collisions=True),
    }
    result: dict[str, dict[str, float]] = {}
    for scenario in ("stand", "random"):
        rates: dict[str, list[float]] = {name: [] for name in models}
        for repeat in range(cfg.repeats):
            for name, model in models.items():
                rates[name].append(_rollout(model, scenario, cfg, cfg.seed + repeat, False))
        row = {f"{name}_steps_per_s": float(np.median(r)) for name, r in rates.items()}
        row["ratio"] = row["links_steps_per_s"] / row["soles_steps_per_s"]
        for name, model in models.items():
            row[f"{name}_ncon"] = _rollout(model, scenario, cfg, cfg.seed, True)
        result[scenario] = row
    models["meshes"] = build_mujoco_spec(MujocoModelConfig()).compile()
    memory = {}
    for name, model in models.items():
        data = mujoco.MjData(model)
        memory[f"{name}_model_bytes"] = float(model.nbuffer)
        memory[f"{name}_data_bytes"] = float(data.nbuffer + data.narena)
        memory[f"{name}_ngeom"] = float(model.ngeom)
    result["memory"] = memory
    return result


def main() -> None:
    """Print the fitted primitives and the step-rate / memory comparison."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=StepRateConfig.steps, help="steps per timing")
    parser.add_argument("--repeats", type=int, default=StepRateConfig.repeats, help="repeats")
    args = parser.parse_args()
    for p in fit_link_primitives():
        kind = "capsule" if p.geom_type == CAPSULE else "box"
        print(
            f"{p.body:26s} {p.source_mesh:24s} {kind:7s} size {np.round(p.size_m, 3)} "
            f"vol/hull {p.volume_m3 / p.hull_volume_m3:.2f}"
        )
    report = measure_step_rates(StepRateConfig(steps=args.steps, repeats=args.repeats))
    for key, row in report.items():
        print(key, {k: round(v, 3) for k, v in row.items()})


if __name__ == "__main__":
    main()
