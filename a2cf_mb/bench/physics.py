"""``a2cf-mb bench physics``: what each MuJoCo setting of the G1 flat physics costs and changes.

The env's physics model (:func:`rl.envs.model.build_physics_model`: flat floor, 4 sole spheres,
link primitives, Newton solver) is the reference. Each variant changes one setting: solver
iterations and tolerance, line-search iterations, the friction cone, the integrator, or the soles
(one box per sole in place of the 4 spheres). N robots start from the standing pose and are
stepped by one ``Rollout`` with the same random joint targets (held 4 physics steps, as the env's
decimation holds an action); the variants are timed alternately, best of ``repeats``, in the same
run. Reported per variant: physics steps/s, the ratio to the reference, and how far its
trajectories drift from the reference's (mean |joint angle difference| over the rollout, and the
pelvis height difference at the end), so a faster setting that changes the motion shows it.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from a2cf_mb.bench import register_benchmark
from rl.envs.model import build_physics_model, model_layout
from robots import g1


@dataclass(frozen=True)
class PhysicsBenchConfig:
    """Sizes of the physics-settings benchmark."""

    num_envs: int = 64  # robots stepped together [-]
    num_steps: int = 400  # physics steps per measurement (2 s at 5 ms) [-]
    repeats: int = 3  # measurements per variant, best kept [-]
    num_threads: int = 1  # physics threads [-]
    target_std: float = 0.3  # std of the random joint targets, in action units [-]
    seed: int = 0  # random seed of the targets [-]
    output: str = ""  # optional json file for the figures


def _box_soles(spec: mujoco.MjSpec) -> None:
    """Replace each sole's 4 contact spheres by one box spanning them (a spec hook)."""
    corners = np.asarray(g1.sole_corners_m())
    half = 0.5 * (corners.max(axis=0) - corners.min(axis=0))
    centre = np.asarray(g1.SOLE_CENTER_OFFSET_M) + 0.5 * (corners.max(axis=0) + corners.min(axis=0))
    for frame in g1.SOLE_FRAMES:
        spheres = [geom for geom in spec.geoms if geom.name.startswith(f"{frame}_")]
        if not spheres:
            raise RuntimeError(f"no contact spheres named {frame}_* in the G1 spec")
        body, template = spheres[0].parent, spheres[0]
        thickness = 0.01
        body.add_geom(
            name=f"{frame}_box",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[half[0], half[1], thickness],
            pos=[centre[0], centre[1], centre[2] + thickness],
            contype=template.contype,
            conaffinity=template.conaffinity,
            condim=template.condim,
            friction=list(template.friction),
            group=template.group,
        )
        for geom in spheres:
            spec.delete(geom)


def _with_option(**option: object) -> Callable[[], mujoco.MjModel]:
    def build() -> mujoco.MjModel:
        model = build_physics_model()
        for name, value in option.items():
            setattr(model.opt, name, value)
        return model

    return build


VARIANTS: dict[str, Callable[[], mujoco.MjModel]] = {
    "reference": build_physics_model,
    "iterations 10, line search 20 (mjlab)": _with_option(iterations=10, ls_iterations=20),
    "iterations 4, line search 10": _with_option(iterations=4, ls_iterations=10),
    "tolerance 1e-6": _with_option(tolerance=1e-6),
    "line search 10": _with_option(ls_iterations=10),
    "elliptic cone": _with_option(cone=int(mujoco.mjtCone.mjCONE_ELLIPTIC)),
    "euler integrator": _with_option(integrator=int(mujoco.mjtIntegrator.mjINT_EULER)),
    "box soles": lambda: build_physics_model(terrain=_box_soles),
}
"""Variant name -> builder of its model; each changes one setting of the reference."""


def run_physics_benchmark(cfg: PhysicsBenchConfig = PhysicsBenchConfig()) -> dict:
    """Build every variant, time the same rollout on each, return the figures."""
    models = {name: build() for name, build in VARIANTS.items()}
    ref = models["reference"]
    lay = model_layout(ref)
    for name, model in models.items():
        if model.nq != ref.nq or model.nu != ref.nu:
            raise RuntimeError(f"variant {name!r} changed the model's layout")
    rng = np.random.default_rng(cfg.seed)
    noise = rng.normal(0.0, cfg.target_std, (cfg.num_envs, cfg.num_steps // 4 + 1, g1.NUM_JOINTS))
    held = np.repeat(noise, 4, axis=1)[:, : cfg.num_steps] * g1.ACTION_SCALE_RAD
    ctrl = g1.STAND_JOINT_POS_RAD + held
    start_state = np.tile(lay.stand_state, (cfg.num_envs, 1))
    best = dict.fromkeys(models, 0.0)
    states: dict[str, np.ndarray] = {}
    with rollout.Rollout(nthread=cfg.num_threads) as runner:
        datas = {k: [mujoco.MjData(m) for _ in range(cfg.num_threads)] for k, m in models.items()}
        for _ in range(cfg.repeats):
            for key, model in models.items():
                start = time.perf_counter()
                state, _ = runner.rollout(
                    [model] * cfg.num_envs, datas[key], start_state, ctrl,
                    control_spec=int(mujoco.mjtState.mjSTATE_CTRL), initial_warmstart=None,
                )  # fmt: skip
                rate = cfg.num_envs * cfg.num_steps / (time.perf_counter() - start)
                best[key] = max(best[key], rate)
                states[key] = state
    q0 = lay.qpos.start
    joints = slice(q0 + 7, q0 + 7 + g1.NUM_JOINTS)
    rows = []
    for key in models:
        dq = np.abs(states[key][..., joints] - states["reference"][..., joints])
        dz = states[key][:, -1, q0 + 2] - states["reference"][:, -1, q0 + 2]
        rows.append(
            {
                "variant": key,
                "physics_steps_per_s": best[key],
                "rate_over_reference": best[key] / best["reference"],
                "mean_joint_drift_rad": float(dq.mean()),
                "mean_abs_pelvis_height_drift_m": float(np.abs(dz).mean()),
                "fallen_fraction": float((states[key][:, -1, q0 + 2] < 0.45).mean()),
            }
        )
    return {"config": dataclasses.asdict(cfg), "mujoco": mujoco.__version__, "variants": rows}


def format_results(results: dict) -> str:
    """One line per variant."""
    lines = [
        f"G1 flat physics settings, MuJoCo {results['mujoco']} "
        f"({results['config']['num_envs']} robots, {results['config']['num_steps']} steps):",
        f"  {'variant':<40} {'steps/s':>9} {'x ref':>6} {'joint drift':>12} {'z drift':>8} "
        f"{'fallen':>7}",
    ]
    for row in results["variants"]:
        lines.append(
            f"  {row['variant']:<40} {row['physics_steps_per_s']:>9.0f} "
            f"{row['rate_over_reference']:>6.2f} {row['mean_joint_drift_rad']:>10.3f} rad "
            f"{row['mean_abs_pelvis_height_drift_m']:>6.3f} m {row['fallen_fraction']:>7.2f}"
        )
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench physics``."""
    register_benchmark(
        subparsers,
        "physics",
        "G1 flat physics: steps/s and drift of each solver, cone, integrator and sole setting",
        PhysicsBenchConfig,
        run_physics_benchmark,
        format_results,
    )
