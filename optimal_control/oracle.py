"""The oracle pipeline: reference -> wrench QP alpha sweep -> eta0 -> OracleArtifact on disk.

One function per task solve (:func:`solve_walk`, :func:`solve_dance`); both go through
:func:`solve_reference_oracle`, which the backflip (or any new task) can call with its own
reference, extra summary fields and extra arrays.

Besides the swept alphas the artifact carries an *upper envelope*: the no-contact wrench
(both soles off, alpha = 1), i.e. the pelvis wrench that would replace the ground altogether
(``extra_no_contact_wrench_w``). alpha = 0 is not swept: a pelvis wrench cannot hold limbs whose
joints are passive, so that QP is infeasible (see :mod:`optimal_control.wrench_qp`).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from optimal_control.artifact import VIDEO_FILE, OracleArtifact, build_artifact
from optimal_control.bounds import BoundRule, envelope_per_phase
from optimal_control.files import check_output_folder
from optimal_control.reference import Reference
from optimal_control.validation import require_finite_fields, require_ranges
from optimal_control.wrench_qp import WrenchProfile, WrenchQP, WrenchQPConfig


@dataclass(frozen=True)
class OracleConfig:
    """Alpha sweep, bound rule, QP options and outputs of an oracle solve."""

    alphas: tuple[float, ...] = (1.0, 0.75, 0.5)  # torque-limit fractions swept [-]
    novice_alpha: float = 0.5  # alpha of the novice model eta0 is derived from [-]
    percentile: float = 95.0  # eta0 rule: percentile of |w| per phase and axis [percent]
    margin: float = 1.5  # eta0 rule: multiplier on the percentile [-]
    floor_force_n: float = 5.0  # eta0 rule: least bound of a force axis [N]
    floor_torque_nm: float = 2.0  # eta0 rule: least bound of a torque axis [N m]
    bound_frames: str = "aided"  # eta0 rule reads frames that need help ("aided") or "all"
    friction_coefficient: float = 0.7  # sole friction pyramid slope [-]
    # > 0: the reference's phases become time bins of this length, so eta0 (and the coach's clip,
    # and a tracking run's curriculum) work per bin of the motion; 0: the reference's own phases
    phase_bin_s: float = 0.0  # eta0 per time bin of this length [s]; 0: per phase
    video: bool = True  # render the reference to reference.mp4 (MuJoCo, EGL)
    video_width: int = 400  # video width [px]
    video_height: int = 300  # video height [px]
    progress: bool = True  # show a progress bar over the frames
    out: str = ""  # artifact folder; empty = artifacts/<task>-<UTC timestamp>
    overwrite: bool = False  # replace an existing --out folder (as a whole, atomically)

    def __post_init__(self) -> None:
        """Reject NaN / inf values, naming the field and its flag."""
        require_finite_fields(self)
        if self.phase_bin_s < 0:
            raise ValueError(
                f"--phase-bin-s must be >= 0 s (0: the reference's own phases), got "
                f"{self.phase_bin_s}"
            )
        require_ranges(self, {
            "alphas": (0.0, 10.0, ""), "novice_alpha": (0.0, 10.0, ""),
            "percentile": (0.0, 100.0, "percent"), "margin": (0.0, 100.0, ""),
            "floor_force_n": (0.0, 1e4, "N"), "floor_torque_nm": (0.0, 1e4, "N m"),
            "friction_coefficient": (0.0, 10.0, ""), "phase_bin_s": (0.0, 3600.0, "s"),
            "video_width": (16, 8192, "px"), "video_height": (16, 8192, "px"),
        })  # fmt: skip

    def rule(self) -> BoundRule:
        """The eta0 rule of this config."""
        return BoundRule(
            percentile=self.percentile,
            margin=self.margin,
            floor_force_n=self.floor_force_n,
            floor_torque_nm=self.floor_torque_nm,
            novice_alpha=self.novice_alpha,
            frames=self.bound_frames,
        )


def default_output_dir(task: str) -> Path:
    """``artifacts/<task>-<YYYYmmdd-HHMMSS>`` (UTC) in the working directory; ``-2``, ``-3``, ...
    is appended when a run of the same second took the name (never an existing folder)."""
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d-%H%M%S")
    folder = Path("artifacts") / f"{task}-{stamp}"
    k = 2
    while folder.exists():
        folder = Path("artifacts") / f"{task}-{stamp}-{k}"
        k += 1
    return folder


def resolve_output(task: str, cfg: OracleConfig) -> OracleConfig:
    """``cfg`` with its output folder fixed (the timestamped default resolved once) and checked
    before any work: writable, and not an existing folder unless ``cfg.overwrite``."""
    folder = Path(cfg.out) if cfg.out else default_output_dir(task)
    check_output_folder(folder, cfg.overwrite)
    return dataclasses.replace(cfg, out=str(folder))


def sweep_alphas(
    ref: Reference, cfg: OracleConfig = OracleConfig()
) -> tuple[dict[float, WrenchProfile], dict[str, float]]:
    """Wrench profiles of ``ref`` for every alpha of the sweep (novice alpha included).

    Returns the profiles and the wall time of each sweep [s] keyed ``alpha_<a>``.
    """
    alphas = sorted(set(cfg.alphas) | {cfg.novice_alpha}, reverse=True)
    profiles, timings = {}, {}
    for alpha in alphas:
        qp = WrenchQP(WrenchQPConfig(alpha=alpha, friction_coefficient=cfg.friction_coefficient))
        start = time.perf_counter()
        profiles[alpha] = qp.solve_reference(ref, progress=cfg.progress)
        timings[f"alpha_{alpha:.2f}"] = time.perf_counter() - start
    return profiles, timings


def time_bin_phases(ref: Reference, bin_s: float) -> Reference:
    """``ref`` with its phases replaced by consecutive time bins of ``bin_s`` [s] from its first
    frame, named ``t<start>s`` (``t0s``, ``t1s``, ... for 1 s bins); the last bin may be shorter."""
    if bin_s <= 0:
        raise ValueError(f"time bins need a length > 0 s, got {bin_s}")
    rel_s = np.asarray(ref.time_s, dtype=float) - float(ref.time_s[0])
    phase = np.floor(rel_s / bin_s + 1e-6).astype(np.int64)
    names = tuple(f"t{k * bin_s:g}s" for k in range(int(phase.max()) + 1))
    return dataclasses.replace(ref, phase=phase, phase_names=names).validate()


def no_contact_profile(ref: Reference, cfg: OracleConfig = OracleConfig()) -> WrenchProfile:
    """The upper envelope: the wrench along ``ref`` with both soles off the ground (alpha = 1)."""
    airborne = dataclasses.replace(ref, contacts=np.zeros_like(ref.contacts))
    qp = WrenchQP(WrenchQPConfig(alpha=1.0, friction_coefficient=cfg.friction_coefficient))
    return qp.solve_reference(airborne)


def solve_reference_oracle(
    task: str,
    ref: Reference,
    cfg: OracleConfig = OracleConfig(),
    extra_summary: dict | None = None,
    extra_arrays: dict[str, np.ndarray] | None = None,
    novice_model: str = "",
    finish: Callable[[OracleArtifact], None] | None = None,
    write_extra: Callable[[OracleArtifact, Path], None] | None = None,
) -> tuple[OracleArtifact, Path]:
    """Run the sweep along ``ref``, derive eta0, render, save; returns the artifact and folder.

    ``finish`` may add summary fields that need eta0 before the artifact is saved; ``write_extra``
    writes task files into the folder being built (see :meth:`OracleArtifact.save`).
    """
    if not cfg.alphas:
        raise ValueError("OracleConfig.alphas is empty; give at least one alpha, e.g. 1.0 0.5.")
    cfg = resolve_output(task, cfg)
    folder = Path(cfg.out)
    if cfg.phase_bin_s > 0:
        ref = time_bin_phases(ref, cfg.phase_bin_s)
    profiles, timings = sweep_alphas(ref, cfg)
    upper = no_contact_profile(ref, cfg)
    num_phases = len(ref.phase_names)
    upper_env = envelope_per_phase(upper.wrench_w, ref.phase, num_phases)
    summary = {
        "sweep_wall_time_s": timings,
        "no_contact_envelope": {k: np.nan_to_num(v).tolist() for k, v in upper_env.items()},
        **(extra_summary or {}),
    }
    arrays = {"no_contact_wrench_w": upper.wrench_w, **(extra_arrays or {})}
    art = build_artifact(task, ref, profiles, cfg.rule(), novice_model, summary, arrays)
    if finish is not None:
        finish(art)

    def write_files(art: OracleArtifact, tmp: Path) -> None:
        if cfg.video:
            from optimal_control.render import (
                RenderConfig,
                RenderUnavailableError,
                render_reference,
            )

            try:
                render_reference(
                    ref,
                    tmp / VIDEO_FILE,
                    RenderConfig(width=cfg.video_width, height=cfg.video_height),
                    wrench_w=art.novice_profile.wrench_w,
                )
                art.video = VIDEO_FILE
            except RenderUnavailableError as err:
                art.video_note = f"no video: {err}"
            except Exception as err:  # a GL failure mid-video: the solve's artifact still counts
                art.video_note = f"no video: rendering failed ({type(err).__name__}: {err})"
        else:
            art.video_note = "no video: disabled (--no-video)"
        if write_extra is not None:
            write_extra(art, tmp)

    art.save(folder, overwrite=cfg.overwrite, write_extra=write_files)
    return art, folder


def solve_walk(walk_cfg=None, cfg: OracleConfig = OracleConfig()) -> tuple[OracleArtifact, Path]:
    """Plan a placo walk at the commanded velocity and write its oracle artifact."""
    from optimal_control.walk import WalkConfig, plan_walk

    walk_cfg = walk_cfg or WalkConfig()
    cfg = resolve_output("walk", cfg)
    start = time.perf_counter()
    plan = plan_walk(walk_cfg)
    ref_time = time.perf_counter() - start
    summary = {
        "walk_config": dataclasses.asdict(walk_cfg),
        "reference_time_s": ref_time,
        "placo_planning_time_s": plan.planning_time_s,
        "placo_ik_time_s": plan.ik_time_s,
        "max_stance_slip_m": plan.max_stance_slip_m,
        "footsteps": [
            {"side": side, "x_m": float(x), "y_m": float(y), "yaw_rad": float(yaw)}
            for side, (x, y, yaw) in zip(plan.footstep_sides, plan.footsteps_w, strict=True)
        ],
    }
    return solve_reference_oracle("walk", plan.reference, cfg, summary)


def solve_dance(
    dance_cfg=None,
    cfg: OracleConfig = OracleConfig(),
    clip: str = "",
    clip_cfg=None,
    clip_frames: str = "",
) -> tuple[OracleArtifact, Path]:
    """Oracle artifact of the built-in dance, or of a motion clip file when ``clip`` is given
    (frames ``clip_frames`` "A:B" of it: source frames A inclusive to B exclusive, as
    ``train --reference-frames`` reads them; empty: all)."""
    from optimal_control.dance import DanceConfig, built_in_dance, pose_summary
    from optimal_control.motion_clip import (
        ClipConfig,
        plausibility_problems,
        read_clip,
        reference_from_clip_rows,
    )
    from optimal_control.reference_sources import (
        CLIP_FRAMES_FLAG,
        parse_frames,
        read_clip_segment,
        reference_fingerprint,
    )

    frames = parse_frames(clip_frames, CLIP_FRAMES_FLAG)
    if frames is not None and not clip:
        raise ValueError(
            f"{CLIP_FRAMES_FLAG} {clip_frames} takes a segment of a clip: give --clip FILE too "
            "(the built-in dance has no source frames)"
        )
    cfg = resolve_output("dance", cfg)
    start = time.perf_counter()
    finish = None
    if clip:
        clip_cfg = clip_cfg or ClipConfig()
        if frames is None:  # the whole file, read as before segments existed
            rows, fps = read_clip(clip, clip_cfg)
        else:  # the segment and its checks as train --reference-frames reads them
            rows, fps = read_clip_segment(clip, frames, clip_cfg, flag=CLIP_FRAMES_FLAG)
        ref, plausibility = reference_from_clip_rows(
            rows, fps, clip_cfg, "dance", source=f"Motion clip '{clip}'"
        )
        summary = {
            "source": {
                "clip": str(clip),
                "frames": list(frames) if frames is not None else None,
                "fingerprint": reference_fingerprint(ref),
                "clip_config": dataclasses.asdict(clip_cfg),
            },
            "clip_plausibility": plausibility,
        }

        def finish(art: OracleArtifact) -> None:
            report = art.extra_summary["clip_plausibility"]
            known = len(plausibility_problems(report, clip_cfg))  # warned at load
            if 1.0 in art.profiles:
                report["unaided_share_alpha_1"] = float(art.profiles[1.0].unaided.mean())
            report["problems"] = plausibility_problems(report, clip_cfg)
            for problem in report["problems"][known:]:
                warnings.warn(f"Motion clip '{clip}': {problem}", stacklevel=3)

    else:
        dance_cfg = dance_cfg or DanceConfig()
        plan = built_in_dance(dance_cfg)
        ref = plan.reference
        summary = {
            "source": {"built_in": True, "dance_config": dataclasses.asdict(dance_cfg)},
            "placo_ik_time_s": plan.ik_time_s,
            "max_foot_error_m": plan.max_foot_error_m,
        }
    summary["reference_time_s"] = time.perf_counter() - start
    summary["pose_summary"] = pose_summary(ref)
    return solve_reference_oracle("dance", ref, cfg, summary, finish=finish)


def format_summary(art: OracleArtifact, folder: Path) -> str:
    """A few lines for the terminal: where, eta0 per phase, solver stats per alpha."""
    lines = [f"oracle artifact: {folder}"]
    for name, bound in art.eta0_dict().items():
        f = ", ".join(f"{x:.1f}" for x in bound["force_n"])
        m = ", ".join(f"{x:.1f}" for x in bound["torque_nm"])
        lines.append(f"  eta0[{name}]: force [{f}] N, torque [{m}] N m")
    for alpha in sorted(art.profiles, reverse=True):
        s = art.profiles[alpha].stats()
        lines.append(
            f"  alpha {alpha:.2f}: {s['mean_time_ms']:.3f} ms/frame, unaided "
            f"{100 * s['unaided_fraction']:.0f}%, solved {100 * s['solved_fraction']:.0f}%, "
            f"max |w| {s['max_wrench_norm']:.1f}"
        )
    lines.append(f"  video: {art.video or art.video_note}")
    return "\n".join(lines)
