"""`a2cf-mb solve-backflip`: TO -> audit -> MuJoCo playback -> novice model -> OracleArtifact.

:func:`solve_backflip` is the one library call behind the command. It solves the TO (cold, or
warm-started from ``--warm-start`` or from the cache of the same problem), audits the solution
(:mod:`.audit`; a failing solution is saved as ``failed_solution.npz`` with ``audit.json`` and an
error is raised, nothing is shipped), samples it at 50 Hz as the oracle :class:`Reference`, plays
it back in MuJoCo with and without the pelvis wrench, runs the oracle's alpha sweep (the novice
model, :mod:`.novice`) and writes the same :class:`OracleArtifact` as walk / dance, with the TO's
trajectories, phase timings, solver statistics, audit, playback and the eta0-vs-paper table in it.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from optimal_control.artifact import OracleArtifact
from optimal_control.backflip.audit import AuditConfig, AuditReport, audit_solution
from optimal_control.backflip.config import AIR_PHASE, PHASE_NAMES, BackflipConfig
from optimal_control.backflip.novice import (
    NOVICE_MODEL,
    compare_with_paper,
    comparison_markdown,
    momentum_deficit_wrench,
    takeoff_momentum,
)
from optimal_control.backflip.playback import (
    PlaybackConfig,
    air_inverse_dynamics_gap_nm,
    play_back,
    play_flight,
    reference_centroidal,
)
from optimal_control.backflip.sagittal import (
    MOVED_JOINTS,
    SagittalModel,
    build_sagittal_model,
    sagittal_model_for,
)
from optimal_control.backflip.solve import (
    SolveResult,
    StaleCacheError,
    cache_path,
    load_cached_solution,
    reuse_solution,
    save_solution,
    solve_backflip_to,
)
from optimal_control.backflip.trajectory import (
    SampledFlip,
    fine_grid_limit_report,
    sample_solution,
)
from optimal_control.backflip.transcription import Solution
from optimal_control.files import atomic_write_json, atomic_write_text
from optimal_control.oracle import OracleConfig, resolve_output, solve_reference_oracle
from optimal_control.validation import require_finite_fields


@dataclass(frozen=True)
class BackflipOracleConfig(OracleConfig):
    """The oracle options with the backflip's alpha sweep."""

    alphas: tuple[float, ...] = (1.0, 0.5, 0.3)  # torque-limit fractions swept [-]


@dataclass(frozen=True)
class OutputConfig:
    """What the pipeline writes and how it samples."""

    rate_hz: float = 50.0  # artifact sample rate [Hz]
    use_cache: bool = True  # warm-start from the cached solution of the same problem
    # once its constraints are re-checked: no solver build, no IPOPT
    reuse_cached_solution: bool = True  # with use_cache: reuse it, not re-solve its last stage
    playback: bool = True  # run the MuJoCo playback check

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field and its flag."""
        require_finite_fields(self)


class BackflipAuditError(RuntimeError):
    """A solved backflip failed its audit; it was not written as an artifact."""


def _phase_table(sol: Solution, grid) -> dict[str, dict[str, float]]:
    times = sol.knot_times_s(grid)
    starts = np.concatenate([[0], np.cumsum(grid.intervals)])
    return {
        name: {
            "start_s": float(times[starts[i]]),
            "duration_s": float(sol.durations_s[i]),
            "intervals": int(grid.intervals[i]),
        }
        for i, name in enumerate(PHASE_NAMES)
    }


def _wrench_per_phase(wrench_w: np.ndarray, phase: np.ndarray) -> dict[str, list[float]]:
    return {
        name: (np.abs(wrench_w[phase == p]).max(axis=0).tolist() if np.any(phase == p) else None)
        for p, name in enumerate(PHASE_NAMES)
    }


def write_backflip_plots(
    flip: SampledFlip, playbacks: dict, folder: Path, model: SagittalModel | None = None
) -> list[Path]:
    """Phase-shaded joint torques and TO wrench, pitch angle (reference and MuJoCo playbacks)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    t = flip.time_s

    def shade(ax):
        for p, name in enumerate(PHASE_NAMES):
            m = flip.phase == p
            if np.any(m):
                ax.axvspan(t[m][0], t[m][-1] + flip.dt_s, color=colors[p], alpha=0.12, label=name)

    model = model or build_sagittal_model()
    paths = []
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    shade(axes[0])
    for cols, name in zip(model.joint_columns, MOVED_JOINTS, strict=True):
        c = cols[0]
        axes[0].plot(t, flip.tau_nm[:, c] / model.effort_limit_nm[c], label=name)
    axes[0].set_ylabel("tau / tau_max (left side) [-]")
    axes[0].legend(fontsize=7, ncol=5)
    axes[0].grid(alpha=0.3)
    shade(axes[1])
    for i, axis in enumerate(("fx", "fy", "fz", "mx", "my", "mz")):
        axes[1].plot(t, flip.wrench_w[:, i], label=axis)
    axes[1].set_ylabel("TO pelvis wrench [N, N m]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(fontsize=7, ncol=6)
    axes[1].grid(alpha=0.3)
    fig.suptitle("backflip TO: joint torques and pelvis wrench (phases shaded)")
    fig.tight_layout()
    paths.append(folder / "backflip_torque_wrench.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)

    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    for ax in axes:
        shade(ax)
    axes[0].plot(t, np.degrees(flip.r[:, 2]), "k", label="TO reference")
    axes[1].plot(t, flip.q[:, 2], "k", label="TO reference")
    axes[2].plot(t, reference_centroidal(flip)[0], "k", label="TO reference")
    axes[3].axhline(0.0, color="k", lw=0.8)
    for key, (res, pitch, height, t_sim, log) in playbacks.items():
        axes[0].plot(t_sim, np.degrees(pitch), label=f"MuJoCo {key}")
        axes[1].plot(t_sim, height, label=f"MuJoCo {key} (done: {res.completed_flip})")
        axes[2].plot(t_sim, log["ang_momentum_y_nms"], label=f"MuJoCo {key}")
        axes[3].plot(t_sim, np.degrees(log["waist_pitch_error_rad"]), label=f"MuJoCo {key}")
    axes[0].set_ylabel("pelvis pitch [deg]")
    axes[1].set_ylabel("pelvis height [m]")
    axes[2].set_ylabel("centroidal L_y [N m s]")
    axes[3].set_ylabel("held waist pitch\nerror [deg]")
    axes[3].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    fig.tight_layout()
    paths.append(folder / "backflip_pitch_height.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    return paths


def _playbacks(flip_sim: SampledFlip, cfg: PlaybackConfig, turn_rad: float) -> dict:
    from robots.conventions import quat_wxyz_to_matrix

    out = {}
    for gain in cfg.gain_scales:
        for with_w in (True, False):
            log: dict = {}
            res, qpos = play_back(flip_sim, with_w, cfg, turn_rad, gain, log=log)
            rot = quat_wxyz_to_matrix(qpos[:, 3:7])
            pitch = np.unwrap(np.arctan2(rot[:, 0, 2], rot[:, 2, 2]))
            t_sim = flip_sim.dt_s * np.arange(1, len(qpos) + 1)
            key = f"gain{gain:g}_{'with' if with_w else 'without'}_w"
            out[key] = (res, pitch, qpos[:, 2], t_sim, log)
    return out


def _flight_checks(flip_sim: SampledFlip, cfg: PlaybackConfig) -> dict:
    """:func:`play_flight` (Air phase alone, from the reference take-off state) per gain and w."""
    return {
        f"gain{gain:g}_{'with' if with_w else 'without'}_w": play_flight(
            flip_sim, with_w, cfg, gain
        ).to_dict()
        for gain in cfg.gain_scales
        for with_w in (True, False)
    }


def solve_backflip(
    cfg: BackflipConfig = BackflipConfig(),
    oracle_cfg: OracleConfig = BackflipOracleConfig(),
    playback_cfg: PlaybackConfig = PlaybackConfig(),
    out_cfg: OutputConfig = OutputConfig(),
    audit_cfg: AuditConfig = AuditConfig(),
) -> tuple[OracleArtifact, Path, dict]:
    """Solve, audit, check and write the backflip oracle artifact.

    Returns the artifact, its folder and a report dict (solver, audit, playback figures).

    Raises:
        InfeasibleBackflipError: the TO found no feasible motion (groups named, iterate saved).
        BackflipAuditError: the solution failed the audit (saved, not shipped).
    """
    cfg.validate()
    oracle_cfg = resolve_output("backflip", oracle_cfg)
    folder = Path(oracle_cfg.out)
    # Failure files never go into an existing artifact (it would no longer match its manifest).
    failure_dir = folder if not folder.exists() else folder.with_name(folder.name + "-failed")
    model = sagittal_model_for(cfg)
    warm = None
    warm_source = cfg.warm_start
    cached = cache_path(cfg) if cfg.cache_dir else None
    cache_note = ""
    if not cfg.warm_start and out_cfg.use_cache and cached is not None and cached.is_file():
        try:
            warm = load_cached_solution(cached, cfg)
            warm_source = str(cached)
        except StaleCacheError as err:
            cache_note = f"ignored the stale cache file (it will be replaced): {err}"
            warnings.warn(cache_note, stacklevel=2)
        except ValueError as err:
            cache_note = f"ignored the corrupt cache file (it will be replaced): {err}"
            warnings.warn(cache_note, stacklevel=2)
            cached.unlink(missing_ok=True)
    t0 = time.perf_counter()
    result: SolveResult | None = None
    if warm is not None and out_cfg.reuse_cached_solution:
        result = reuse_solution(cfg, warm, model)
        if result is None:
            cache_note = (
                f"the cached solution {cached} does not meet the problem's constraints to "
                "1e-6: re-solved from it"
            )
            warnings.warn(cache_note, stacklevel=2)
    if result is None:
        result = solve_backflip_to(
            cfg, model, warm_start=warm, failure_path=failure_dir / "last_iterate.npz"
        )
    solve_wall = time.perf_counter() - t0
    sol = result.solution
    grid = result.transcription.grid
    audit: AuditReport = audit_solution(sol, cfg, model, audit_cfg, grid)
    if not audit.passed:
        failure_dir.mkdir(parents=True, exist_ok=True)
        save_solution(sol, failure_dir / "failed_solution.npz")
        atomic_write_json(failure_dir / "audit.json", audit.to_dict())
        raise BackflipAuditError(
            "The solved backflip FAILED its audit and was not written as an artifact:\n  - "
            + "\n  - ".join(audit.failures())
            + f"\nSolution and audit saved in {failure_dir} (failed_solution.npz, audit.json)."
        )
    if cached is not None and not result.reused_cached_solution:
        try:
            save_solution(sol, cached, cfg)
        except OSError as err:  # the cache only saves time: report, do not fail the run
            cache_note = f"could not write the cache file {cached}: {err}"
            warnings.warn(cache_note, stacklevel=2)

    flip = sample_solution(sol, grid, model, out_cfg.rate_hz)
    ref = flip.to_reference()
    playback_report = {}
    playbacks = {}
    if out_cfg.playback:
        # MuJoCo steps at exactly 5 ms: keep that step (the last sample is <= 5 ms before the end)
        flip_sim = sample_solution(sol, grid, model, 1.0 / 0.005, through_end=False)
        playbacks = _playbacks(flip_sim, playback_cfg, cfg.turn_rad)
        playback_report = {k: v[0].to_dict() for k, v in playbacks.items()}
        playback_report["flight_only"] = _flight_checks(flip_sim, playback_cfg)
        gap = air_inverse_dynamics_gap_nm(flip_sim)
        playback_report["air_inverse_dynamics_gap_nm"] = {
            "median": float(np.median(gap)),
            "max": float(np.max(gap)),
            "samples_over_1nm": int(np.sum(gap > 1.0)),
            "samples": len(gap),
        }
        playback_report["config"] = dataclasses.asdict(playback_cfg)

    k0 = grid.takeoff_knot
    q_to, v_to, _ = model.to_full(sol.r[k0 : k0 + 1], sol.rd[k0 : k0 + 1], sol.rdd[k0 : k0 + 1])
    momentum = takeoff_momentum(model.robot.model, q_to[0], v_to[0])
    flight = float(sol.durations_s[AIR_PHASE])
    solver = result.stats_dict()
    solver["wall_time_s"] = solve_wall
    solver["warm_start_from"] = warm_source or None
    solver["cache_note"] = cache_note
    limits = fine_grid_limit_report(sol, grid, model)
    produced_by = {
        "solve": "reused"
        if result.reused_cached_solution
        else "warm"
        if result.warm_started
        else "cold",
        "warm_start_from": warm_source or None,
        "ipopt_iterations": result.stats_dict().get("total_iterations"),
        "phase_durations_s": [float(d) for d in sol.durations_s],
    }
    summary = {
        "produced_by": produced_by,
        "fine_grid_limits": limits,
        "to_config": dataclasses.asdict(cfg),
        "reduction": {
            "motion": "left/right symmetric, sagittal (base y = roll = yaw = 0); full 3-D dynamics",
            "moved_joints": list(MOVED_JOINTS),
            "held_joints": "all others at the stand pose (their holding torques are bounded)",
            "contact": "heel and toe points per sole on the centre line, same force on both feet",
        },
        "phases": _phase_table(sol, grid),
        "solver": solver,
        "audit": audit.to_dict(),
        "playback": playback_report,
        "to_wrench_max_per_phase_w": _wrench_per_phase(flip.wrench_w, flip.phase),
        "takeoff_momentum": momentum,
        "momentum_deficit_air_wrench": momentum_deficit_wrench(
            momentum, flight, tuple(sorted(set(oracle_cfg.alphas), reverse=True))
        ),
    }
    arrays = {
        "to_tau_nm": flip.tau_nm,
        "to_sole_force_n": flip.force_n,
        "to_wrench_w": flip.wrench_w,
        "to_pitch_rad": flip.r[:, 2],
        "knot_r": sol.r,
        "knot_rd": sol.rd,
        "knot_rdd": sol.rdd,
        "knot_force_n": sol.force_n,
        "knot_wrench_b": sol.wrench_b,
        "phase_durations_s": sol.durations_s,
    }

    def finish(art: OracleArtifact) -> None:
        cmp = compare_with_paper(art.eta0, PHASE_NAMES)
        art.extra_summary["eta0_vs_paper"] = cmp
        for alpha in sorted(art.profiles, reverse=True):
            prof = art.profiles[alpha]
            art.extra_summary.setdefault("novice_wrench_max_per_phase_w", {})[f"{alpha:.2f}"] = (
                _wrench_per_phase(prof.wrench_w, ref.phase)
            )

    def write_extra(art: OracleArtifact, tmp: Path) -> None:
        save_solution(sol, tmp / "solution.npz")
        atomic_write_text(
            tmp / "eta0_vs_paper.md", comparison_markdown(art.extra_summary["eta0_vs_paper"]) + "\n"
        )
        write_backflip_plots(flip, playbacks, tmp / "plots", model)

    art, folder = solve_reference_oracle(
        "backflip", ref, oracle_cfg, summary, arrays, NOVICE_MODEL, finish, write_extra
    )
    report = {
        "solver": solver,
        "audit": audit.to_dict(),
        "playback": playback_report,
        "fine_grid_limits": limits,
    }
    return art, folder, report


def _start_kind(solver: dict) -> str:
    if solver.get("reused_cached_solution"):
        return "cached solution of this problem reused, constraints re-checked"
    return "warm start" if solver["warm_started"] else "cold start"


def format_backflip_summary(art: OracleArtifact, folder: Path, report: dict) -> str:
    """Terminal summary: solve, audit, playback, eta0 table."""
    s = report["solver"]
    a = report["audit"]
    lines = [
        f"backflip artifact: {folder}",
        f"  TO: {s['total_iterations']} IPOPT iterations, {s['solve_time_s']:.1f} s IPOPT + "
        f"{s['build_time_s']:.1f} s build ({_start_kind(s)}), "
        f"{s['num_variables']} variables, max violation {s['max_violation']:.1e}",
        f"  audit: {'PASSED' if a['passed'] else 'FAILED'}; energy dE {a['energy_total_j']['delta_energy']:.1f} J "
        f"= joints {a['energy_total_j']['joint_work']:.1f} + wrench "
        f"{a['energy_total_j']['wrench_work']:.2f} + contacts {a['energy_total_j']['contact_work']:.2e} "
        f"(error {a['energy_total_j']['balance_error']:.1f} J)",
    ]
    lim = report.get("fine_grid_limits")
    if lim:
        lines.append(
            f"  limits on a {lim['rate_hz']:.0f} Hz grid: effort {lim['effort']['max_ratio']:.4f} "
            f"({lim['effort']['joint']}), speed {lim['speed']['max_ratio']:.4f} "
            f"({lim['speed']['joint']}), position beyond range "
            f"{lim['position_beyond_range']['max_ratio']:.2g}; within limits: "
            f"{lim['within_limits']}"
        )
    for key, pb in report["playback"].items():
        if key in ("config", "flight_only", "air_inverse_dynamics_gap_nm"):
            continue
        lines.append(
            f"  MuJoCo playback {key}: flip completed {pb['completed_flip']}, pitch at the "
            f"reference end {np.degrees(pb['pitch_at_reference_end_rad']):.0f} deg, final "
            f"{np.degrees(pb['final_pitch_rad']):.0f} deg, max pitch error "
            f"{np.degrees(pb['max_pitch_error_rad']):.0f} deg, max height error "
            f"{pb['max_height_error_m']:.2f} m; take-off L_y "
            f"{pb['takeoff_ang_momentum_y_nms']:.1f} (TO {pb['ref_takeoff_ang_momentum_y_nms']:.1f})"
            f" N m s, waist pitch error {pb['max_waist_pitch_error_before_takeoff_rad']:.2f} rad"
        )
    for key, fl in report["playback"].get("flight_only", {}).items():
        lines.append(
            f"  MuJoCo flight only (from the TO take-off state, no contacts) {key}: pitch error "
            f"at touch-down {np.degrees(fl['pitch_error_at_touchdown_rad']):.1f} deg"
        )
    lines.append(comparison_markdown(art.extra_summary["eta0_vs_paper"]))
    lines.append(f"  video: {art.video or art.video_note}")
    return "\n".join(lines)
