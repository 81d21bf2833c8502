"""``a2cf-mb bench backflip``: cold vs warm solve of the backflip TO (time, IPOPT iterations).

Cold: the hand-designed initial guess and the full continuation on the pelvis-wrench weight.
Warm: the same problem re-solved from the cold solution (last continuation stage only), which is
what ``solve-backflip`` does when a cached solution of the same problem exists. Reference measured
in the same run: one evaluation of the symbolic inverse dynamics at every knot (the unit of work
of each IPOPT iteration) and a batch of pinocchio RNEA calls; times are also reported as ratios to
it, so figures from machines of different speed compare.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from a2cf_mb.bench import register_benchmark


@dataclass(frozen=True)
class BackflipBenchConfig:
    """Sizes of the backflip benchmark."""

    tiny: bool = False  # the tests' tiny hop instead of the full backflip
    reference_repeats: int = 200  # repeats of the reference evaluation, best kept [-]
    output: str = ""  # optional json file for the figures


def _reference_times(num_knots: int, repeats: int) -> dict[str, float]:
    import pinocchio as pin

    from optimal_control.backflip.sagittal import build_sagittal_model

    model = build_sagittal_model()
    fn = model.inverse_dynamics.map(num_knots)
    rng = np.random.default_rng(0)
    nr = model.lower_r.shape[0]
    r = model.r_stand()[:, None] + 0.1 * rng.normal(size=(nr, num_knots))
    args = (
        r,
        rng.normal(size=(nr, num_knots)),
        rng.normal(size=(nr, num_knots)),
        np.zeros((4, num_knots)),
    )
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - start)
    pmodel = model.robot.model
    data = pmodel.createData()
    q, v, a = model.to_full(r.T, args[1].T, args[2].T)
    best_pin = np.inf
    for _ in range(max(1, repeats // 10)):
        start = time.perf_counter()
        for k in range(num_knots):
            pin.rnea(pmodel, data, q[k], v[k], a[k])
        best_pin = min(best_pin, time.perf_counter() - start)
    return {"casadi_id_all_knots_s": float(best), "pinocchio_rnea_all_knots_s": float(best_pin)}


def run_backflip_benchmark(cfg: BackflipBenchConfig = BackflipBenchConfig()) -> dict:
    """Cold and warm solves and the reference timing; returns the figures."""
    from optimal_control.backflip.config import BackflipConfig, tiny_hop_config
    from optimal_control.backflip.sagittal import build_sagittal_model
    from optimal_control.backflip.solve import solve_backflip_to

    problem = tiny_hop_config() if cfg.tiny else BackflipConfig()
    model = build_sagittal_model()
    start = time.perf_counter()
    cold = solve_backflip_to(problem, model)
    cold_wall = time.perf_counter() - start
    start = time.perf_counter()
    warm = solve_backflip_to(problem, model, warm_start=cold.solution)
    warm_wall = time.perf_counter() - start
    ref = _reference_times(cold.transcription.grid.num_knots, cfg.reference_repeats)
    unit = ref["casadi_id_all_knots_s"]
    out = {
        "problem": "tiny hop" if cfg.tiny else "full backflip",
        "num_variables": int(cold.transcription.nlp["x"].shape[0]),
        "num_constraints": int(cold.transcription.nlp["g"].shape[0]),
        "cold": {
            "wall_s": cold_wall,
            "build_s": cold.build_time_s,
            "ipopt_s": cold.solve_time_s,
            "iterations": cold.total_iterations,
            "stages": [dataclasses.asdict(s) for s in cold.stages],
        },
        "warm": {
            "wall_s": warm_wall,
            "build_s": warm.build_time_s,
            "ipopt_s": warm.solve_time_s,
            "iterations": warm.total_iterations,
        },
        "reference": ref,
        "cold_ipopt_in_id_evaluations": cold.solve_time_s / unit,
        "warm_ipopt_in_id_evaluations": warm.solve_time_s / unit,
        "warm_over_cold_ipopt": warm.solve_time_s / cold.solve_time_s,
    }
    return out


def format_results(res: dict) -> str:
    """Human-readable lines."""
    c, w = res["cold"], res["warm"]
    return "\n".join(
        [
            f"backflip TO ({res['problem']}): {res['num_variables']} variables, "
            f"{res['num_constraints']} constraints",
            f"  cold: {c['wall_s']:.1f} s wall ({c['build_s']:.1f} s build, {c['ipopt_s']:.1f} s "
            f"IPOPT, {c['iterations']} iterations over {len(c['stages'])} stages)",
            f"  warm: {w['wall_s']:.1f} s wall ({w['build_s']:.1f} s build, {w['ipopt_s']:.1f} s "
            f"IPOPT, {w['iterations']} iterations)",
            f"  reference: symbolic ID at all knots {1e3 * res['reference']['casadi_id_all_knots_s']:.2f} ms, "
            f"pinocchio RNEA at all knots {1e3 * res['reference']['pinocchio_rnea_all_knots_s']:.2f} ms",
            f"  IPOPT time in ID evaluations: cold {res['cold_ipopt_in_id_evaluations']:.0f}, "
            f"warm {res['warm_ipopt_in_id_evaluations']:.0f} (warm/cold {res['warm_over_cold_ipopt']:.2f})",
        ]
    )


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench backflip``."""
    register_benchmark(
        subparsers,
        "backflip",
        "backflip TO: cold vs warm solve",
        BackflipBenchConfig,
        run_backflip_benchmark,
        format_results,
    )
