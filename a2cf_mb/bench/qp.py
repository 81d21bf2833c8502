"""``a2cf-mb bench qp``: per-frame cost of the wrench QP against a plain Pinocchio RNEA call.

Along a real reference (the placo walk, or the built-in dance) it measures, per frame and on one
core: Pinocchio ``rnea`` alone (the reference), the QP's model terms (RNEA + Jacobians + equality
matrix), a full frame warm-started (the pipeline), and a full frame solved cold (a fresh proxsuite
QP each frame). Best of ``repeats`` passes, and for the QP also the mean over frames of each
frame's fastest pass (``*_min_per_frame``, robust to preemption of whole passes on a shared
machine); reported in ms and as ratios to ``rnea`` of the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from dataclasses import dataclass

import numpy as np

from a2cf_mb.bench import register_benchmark


@dataclass(frozen=True)
class QPBenchConfig:
    """What the QP benchmark solves."""

    task: str = "walk"  # reference: "walk" (placo, vx 0.5) or "dance" (built-in)
    duration: float = 4.0  # walk length [s] (task walk only)
    alpha: float = 0.5  # torque-limit fraction of the QP [-]
    repeats: int = 3  # passes over the reference per measurement, best kept [-]
    output: str = ""  # optional json file for the figures


def _reference(cfg: QPBenchConfig):
    if cfg.task == "walk":
        from optimal_control.walk import WalkConfig, plan_walk

        return plan_walk(WalkConfig(duration=cfg.duration)).reference
    if cfg.task == "dance":
        from optimal_control.dance import built_in_dance

        return built_in_dance().reference
    raise ValueError(f"bench qp: unknown task '{cfg.task}'; use 'walk' or 'dance'.")


def _best_per_frame_s(fn, frames: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best / frames


def run_qp_benchmark(cfg: QPBenchConfig = QPBenchConfig()) -> dict:
    """Run the benchmark and return its figures (ms per frame and ratios to rnea)."""
    import pinocchio as pin

    from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig

    ref = _reference(cfg)
    n = ref.num_frames
    warm_qp = WrenchQP(WrenchQPConfig(alpha=cfg.alpha))
    cold_qp = WrenchQP(WrenchQPConfig(alpha=cfg.alpha, warm_start=False))
    model, data = warm_qp.robot.model, warm_qp.robot.data()

    def rnea():
        for t in range(n):
            pin.rnea(model, data, ref.q[t], ref.v[t], ref.a[t])

    def terms():
        for t in range(n):
            warm_qp.model_terms(ref.q[t], ref.v[t], ref.a[t])

    profile: dict[str, list] = {"warm": [], "cold": []}

    def warm():
        profile["warm"].append(warm_qp.solve_reference(ref))

    def cold():
        profile["cold"].append(cold_qp.solve_reference(ref))

    per_frame = {
        "rnea": _best_per_frame_s(rnea, n, cfg.repeats),
        "model_terms": _best_per_frame_s(terms, n, cfg.repeats),
        "qp_warm": _best_per_frame_s(warm, n, cfg.repeats),
        "qp_cold": _best_per_frame_s(cold, n, cfg.repeats),
    }
    warm_prof, cold_prof = profile["warm"][-1], profile["cold"][-1]
    # Per frame, the fastest of the passes (each pass solves the same sequence): robust to the
    # preemption a shared machine inflicts on whole passes.
    for key in ("warm", "cold"):
        times = np.stack([p.solve_time_s for p in profile[key]])
        per_frame[f"qp_{key}_min_per_frame"] = float(times.min(axis=0).mean())
    return {
        "config": dataclasses.asdict(cfg),
        "frames": n,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS", ""),
        "ms_per_frame": {k: 1e3 * v for k, v in per_frame.items()},
        "ratio_to_rnea": {k: v / per_frame["rnea"] for k, v in per_frame.items()},
        "mean_iterations": {
            "warm": float(warm_prof.iterations.mean()),
            "cold": float(cold_prof.iterations.mean()),
        },
        "max_wrench_difference_warm_cold": float(
            np.abs(warm_prof.wrench_w - cold_prof.wrench_w).max()
        ),
        "max_residual": float(max(warm_prof.residual.max(), cold_prof.residual.max())),
        "solved_fraction": float(warm_prof.solved.mean()),
    }


def format_results(results: dict) -> str:
    """A short table of the figures."""
    cfg = results["config"]
    lines = [f"wrench QP along the {cfg['task']} reference ({results['frames']} frames), 1 thread:"]
    for key, ms in results["ms_per_frame"].items():
        ratio = results["ratio_to_rnea"][key]
        lines.append(f"  {key:<22} {ms:>8.4f} ms/frame   x{ratio:>7.1f} of rnea")
    it = results["mean_iterations"]
    lines.append(f"  proxsuite iterations: warm {it['warm']:.1f}, cold {it['cold']:.1f}")
    lines.append(
        f"  warm vs cold max |dw| {results['max_wrench_difference_warm_cold']:.2e}, "
        f"max residual {results['max_residual']:.2e}"
    )
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench qp``."""
    register_benchmark(
        subparsers,
        "qp",
        "wrench QP ms/frame vs pinocchio rnea",
        QPBenchConfig,
        run_qp_benchmark,
        format_results,
    )
