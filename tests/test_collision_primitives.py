"""Link collision primitives: they enclose the meshes, weigh nothing, and hold a fallen G1 up."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from robots import g1
from robots.collision_primitives import (
    FOOT_LINKS,
    MERGED_MESHES,
    VISUAL_MESHES_FITTED,
    LinkCollisionConfig,
    StepRateConfig,
    add_link_primitives,
    build_collision_model,
    fit_link_primitives,
    measure_step_rates,
    remove_meshes,
)
from robots.mujoco_model import FLOOR_GEOM, STAND_KEYFRAME, build_mujoco_spec

CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE
BOX = mujoco.mjtGeom.mjGEOM_BOX
SOLE_GEOMS = {f"{s}_{i}" for s in g1.SOLE_FRAMES for i in range(4)}


@pytest.fixture(scope="module")
def primitives():
    """The fitted primitives (cached per process)."""
    return fit_link_primitives()


@pytest.fixture(scope="module")
def soles_model():
    """The mesh-free G1 with the sole spheres only."""
    return build_collision_model(link_collisions=False)


@pytest.fixture(scope="module")
def links_model():
    """The mesh-free G1 with sole spheres and link primitives."""
    return build_collision_model(link_collisions=True)


def _world_vertices_m(model, data, geom):
    mesh = model.geom_dataid[geom]
    start = model.mesh_vertadr[mesh]
    local = model.mesh_vert[start : start + model.mesh_vertnum[mesh]].astype(float)
    return local @ data.geom_xmat[geom].reshape(3, 3).T + data.geom_xpos[geom]


def _outside_distance_m(model, data, geom, points_w):
    """How far each point lies outside a capsule or box geom [m] (0 inside), from MuJoCo's pose."""
    local = (points_w - data.geom_xpos[geom]) @ data.geom_xmat[geom].reshape(3, 3)
    size = model.geom_size[geom]
    if model.geom_type[geom] == BOX:
        return np.linalg.norm(np.maximum(np.abs(local) - size, 0.0), axis=1)
    assert model.geom_type[geom] == CAPSULE
    on_axis = np.zeros_like(local)
    on_axis[:, 2] = np.clip(local[:, 2], -size[1], size[1])
    return np.maximum(np.linalg.norm(local - on_axis, axis=1) - size[0], 0.0)


def test_every_collision_mesh_and_hand_gets_one_primitive(primitives):
    model = build_mujoco_spec().compile()
    meshes = {
        model.mesh(model.geom_dataid[g]).name
        for g in range(model.ngeom)
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        and (model.geom_contype[g] or model.geom_conaffinity[g])
    }
    expected = (meshes | set(VISUAL_MESHES_FITTED)) - set(MERGED_MESHES)
    assert sorted(p.source_mesh for p in primitives) == sorted(expected)
    assert {p.geom_type for p in primitives} == {CAPSULE, BOX}
    by_mesh = {p.source_mesh: p for p in primitives}
    for p in primitives:  # mirrored links get the same primitive
        if p.source_mesh.startswith("left_"):
            right = by_mesh[p.source_mesh.replace("left_", "right_")]
            assert right.geom_type == p.geom_type
            np.testing.assert_allclose(right.size_m, p.size_m, atol=1e-3)


def test_each_primitive_encloses_its_mesh_with_bounded_volume(primitives):
    # Primitives placed on the G1 *with* meshes, checked in MuJoCo's world poses of both.
    spec = build_mujoco_spec()
    add_link_primitives(spec, primitives, LinkCollisionConfig(skip_bodies=()))
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    mesh_geoms = {}
    for g in range(model.ngeom):
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = model.mesh(model.geom_dataid[g]).name
            mesh_geoms.setdefault(MERGED_MESHES.get(mesh, mesh), set()).add((mesh, g))
    for p in primitives:
        geom = model.geom(p.geom_name).id
        assert model.body(model.geom_bodyid[geom]).name == p.body
        # One geom per mesh (the URDF has a visual and a collision geom of the same mesh).
        sources = dict(mesh_geoms[p.source_mesh]).values()
        vertices_w = np.vstack([_world_vertices_m(model, data, g) for g in sources])
        outside_m = _outside_distance_m(model, data, geom, vertices_w)
        assert outside_m.max() <= 1e-6, p.source_mesh  # every vertex inside
        hull_m3 = ConvexHull(vertices_w).volume
        assert hull_m3 == pytest.approx(p.hull_volume_m3, rel=1e-6)
        assert 1.0 <= p.volume_m3 / hull_m3 <= 2.5, (p.source_mesh, p.volume_m3 / hull_m3)


def test_primitives_change_no_mass_inertia_or_com(soles_model, links_model):
    assert links_model.nmesh == 0
    assert links_model.ngeom > soles_model.ngeom + 15
    assert links_model.body_subtreemass[1] == pytest.approx(33.34, abs=0.01)
    for name in ("body_mass", "body_ipos", "body_iquat", "body_inertia"):
        np.testing.assert_allclose(
            getattr(links_model, name), getattr(soles_model, name), atol=1e-12
        )
    coms = []
    for model in (soles_model, links_model):
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
        mujoco.mj_forward(model, data)
        coms.append(data.subtree_com[1].copy())
    np.testing.assert_allclose(coms[1], coms[0], atol=1e-9)


def test_standing_robot_touches_the_floor_with_its_soles_only(links_model):
    data = mujoco.MjData(links_model)
    mujoco.mj_resetDataKeyframe(links_model, data, links_model.key(STAND_KEYFRAME).id)
    mujoco.mj_forward(links_model, data)
    touching = {links_model.geom(c.geom[i]).name for c in data.contact[: data.ncon] for i in (0, 1)}
    assert touching - {FLOOR_GEOM} <= SOLE_GEOMS
    assert touching & SOLE_GEOMS
    floor = links_model.geom(FLOOR_GEOM).id
    for p in fit_link_primitives():
        if p.body in FOOT_LINKS:
            continue
        gap_m = mujoco.mj_geomDistance(
            links_model, data, floor, links_model.geom(p.geom_name).id, 1.0, None
        )
        assert gap_m > 0.01, p.geom_name  # shins, hands clear the floor while standing


def _drop(model, axis, angle_rad, duration_s=2.0):
    """Drop the G1 rotated about a world axis, lowest body 0.3 m above the floor, ctrl = stand."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    mujoco.mju_axisAngle2Quat(data.qpos[3:7], np.asarray(axis, dtype=float), angle_rad)
    mujoco.mj_forward(model, data)
    data.qpos[2] += 0.3 - data.xpos[1:, 2].min()
    for _ in range(round(duration_s / model.opt.timestep)):
        mujoco.mj_step(model, data)
    return data


@pytest.mark.parametrize(
    ("pose", "axis", "angle_rad"),
    [("side", (1, 0, 0), np.pi / 2), ("back", (0, 1, 0), -np.pi / 2)],
)
def test_dropped_robot_comes_to_rest_on_the_floor(soles_model, links_model, pose, axis, angle_rad):
    data = _drop(links_model, axis, angle_rad)
    pelvis = links_model.body(g1.BASE_LINK).id
    assert 0.05 < data.xpos[pelvis, 2] < 0.3, pose
    assert data.xpos[1:, 2].min() > -0.02, pose
    assert np.linalg.norm(data.qvel[:3]) < 0.05, pose  # at rest
    sunk = _drop(soles_model, axis, angle_rad)
    assert sunk.xpos[1:, 2].min() < -0.02, pose
    assert sunk.xpos[pelvis, 2] < 0.0, pose


def _model_with_step(link_collisions: bool):
    spec = remove_meshes(build_mujoco_spec())
    if link_collisions:
        add_link_primitives(spec, fit_link_primitives())
    # A stair step 0.1-0.2 m high (above the feet), with terrain contact bits like the floor.
    spec.worldbody.add_geom(
        name="step",
        type=BOX,
        size=[0.1, 0.5, 0.05],
        pos=[1.0, 0.0, 0.15],
        contype=1,
        conaffinity=3,
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(STAND_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    return model, data


def test_shin_catches_a_stair_edge():
    model, data = _model_with_step(link_collisions=True)
    step, shin = model.geom("step").id, model.geom("left_knee_link_collision").id
    # Slide the step back (x only, so never past the shin) until it overlaps the shin by ~5 mm.
    gap_m = mujoco.mj_geomDistance(model, data, step, shin, 2.0, None)
    assert 0.5 < gap_m < 1.0
    for _ in range(20):
        if gap_m < -0.002:
            break
        model.geom_pos[step, 0] -= gap_m + 0.005
        mujoco.mj_forward(model, data)
        gap_m = mujoco.mj_geomDistance(model, data, step, shin, 2.0, None)
    assert -0.01 < gap_m < -0.002
    shift_m = 1.0 - model.geom_pos[step, 0]
    pairs = {tuple(sorted(model.geom(g).name for g in c.geom)) for c in data.contact[: data.ncon]}
    assert ("left_knee_link_collision", "step") in pairs
    assert not any(name in SOLE_GEOMS for pair in pairs if "step" in pair for name in pair)

    model, data = _model_with_step(link_collisions=False)
    model.geom_pos[model.geom("step").id, 0] -= shift_m
    mujoco.mj_forward(model, data)
    assert not any(model.geom("step").id in c.geom for c in data.contact[: data.ncon])


def test_fit_is_computed_once_and_cannot_be_added_twice(primitives):
    assert fit_link_primitives() is primitives
    spec = remove_meshes(build_mujoco_spec())
    add_link_primitives(spec, primitives)
    with pytest.raises(ValueError, match="called twice"):
        add_link_primitives(spec, primitives)


def test_step_rate_report_and_model_memory():
    # Timings are reported, never asserted (noisy machines); memory is deterministic.
    report = measure_step_rates(StepRateConfig(steps=20, repeats=1))
    for scenario in ("stand", "random"):
        assert report[scenario]["soles_steps_per_s"] > 0
        assert report[scenario]["ratio"] > 0
    memory = report["memory"]
    assert memory["links_model_bytes"] < 1.2 * memory["soles_model_bytes"]
    assert memory["links_model_bytes"] < memory["meshes_model_bytes"] / 50
    assert memory["links_ngeom"] > memory["soles_ngeom"]
