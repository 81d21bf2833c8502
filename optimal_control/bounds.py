"""From a wrench envelope to the initial assist bound eta0 (per task phase and wrench axis).

The A2CF force agent squashes its output into a 6-D hypercube ``eta`` per phase; the paper sets
the initial hypercube ``eta0`` by hand (its Table "Initial Distribution of Spatial Force", kept
here as :data:`PAPER_ETA0` for comparison). The oracle derives it from the wrench a *novice* needs:
the per-frame QP following the reference with torque limits scaled by ``novice_alpha``.

Rule ``percentile_margin`` (the default, :class:`BoundRule`)::

    eta0[p, i] = max(floor_i, margin * percentile_P(|w_i(t)| for frames t of phase p that need help))

with ``floor_i`` = ``floor_force_n`` for the force axes and ``floor_torque_nm`` for the torque axes,
over the frames where the QP converged (a frame the novice cannot do even with help, because a
limb lacks torque, has no meaningful wrench; the artifact counts such frames per phase) and, with
``frames = "aided"`` (default), only those that need help (``|w| > unaided_tol``): the bound must
cover the help *when* it is needed, however rare those moments are in the phase (a dance that is
easy 95 % of the time still needs its hard 5 % covered). ``frames = "all"`` uses every frame.
The floor keeps a little room on axes the envelope says are never needed (a learner deviates from
the reference), the margin covers the learner's deviation on axes that are needed. A phase with no
frame gets the floor. The rule's name and parameters are stored in every artifact.

**Axes.** The QP's wrench ``w`` is world-frame; the env bounds the assist wrench per axis of each
robot's *heading frame* (x forward along the pelvis yaw, z up: :class:`rl.envs.assist_action.
AssistAction`). :func:`wrench_in_heading_frame` turns ``w`` into the reference's heading frame
before the rule reads it, so eta0 bounds the axes the learner's head acts on. On world axes, a clip
that faces another way or turns gets its fx and fy (mx and my) bounds mixed up (an example:
``docs/oracle.md``). For references facing +x (the built-in walk, dance and backflip) both agree.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

AXIS_NAMES = ("fx", "fy", "fz", "mx", "my", "mz")
"""Wrench axes: force [N] then torque [N m] at the pelvis CoM (of a bound: heading-frame axes)."""

PAPER_ETA0: dict[str, dict[str, list[list[float]]]] = {
    "walk": {"all": [[40.0, 40.0, 10.0, 40.0, 40.0, 40.0]]},
    "dance": {"all": [[40.0, 40.0, 40.0, 40.0, 40.0, 40.0]]},
    "backflip": {
        "all": [
            [40.0, 40.0, 10.0, 30.0, 30.0, 10.0],
            [40.0, 40.0, 10.0, 30.0, 30.0, 10.0],
            [40.0, 40.0, 100.0, 30.0, 30.0, 30.0],
            [40.0, 40.0, 100.0, 30.0, 30.0, 30.0],
            [40.0, 40.0, 10.0, 30.0, 30.0, 10.0],
        ]
    },
}
"""The paper's hand-set eta0 rows [fx, fy, fz (N), mx, my, mz (N m)] per task (one row per phase;
backflip phases 0-4 = Stand, Crouch, Jump, Air, Land). Comparison only."""


@dataclass(frozen=True)
class BoundRule:
    """The eta0 rule: a margin times a percentile of |w| per phase and axis, with a floor."""

    name: str = "percentile_margin"  # rule identifier stored in the artifact
    percentile: float = 95.0  # percentile of |w_axis| over the frames of a phase [percent]
    margin: float = 1.5  # multiplier on the percentile [-]
    floor_force_n: float = 5.0  # least eta0 of a force axis [N]
    floor_torque_nm: float = 2.0  # least eta0 of a torque axis [N m]
    novice_alpha: float = 0.5  # torque-limit fraction of the novice model the rule reads [-]
    frames: str = "aided"  # frames the percentile reads: "aided" (need help) or "all"
    unaided_tol: float = 0.5  # |w| at or below which a frame needs no help [N, N m]

    def to_dict(self) -> dict:
        """JSON-ready parameters."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> BoundRule:
        """Inverse of :meth:`to_dict`."""
        return cls(**values)


def wrench_in_heading_frame(wrench_w: np.ndarray, base_quat_xyzw: np.ndarray) -> np.ndarray:
    """World-frame wrenches (T, 6) in the heading frames of pelvis orientations (T, 4) (Pinocchio
    order x y z w): the horizontal force and torque components turned by minus the pelvis yaw."""
    x, y, z, w = np.asarray(base_quat_xyzw, dtype=float).T
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    c, s = np.cos(yaw), np.sin(yaw)
    wrench_w = np.asarray(wrench_w, dtype=float)
    out = wrench_w.copy()
    for k in (0, 3):  # force, then torque
        out[:, k] = c * wrench_w[:, k] + s * wrench_w[:, k + 1]
        out[:, k + 1] = -s * wrench_w[:, k] + c * wrench_w[:, k + 1]
    return out


def eta0_per_phase(
    wrench_w: np.ndarray,
    phase: np.ndarray,
    num_phases: int,
    rule: BoundRule = BoundRule(),
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """Initial bound (num_phases, 6) [N, N m] from a wrench profile (T, 6) and phase ids (T,).

    ``valid`` (T,) bool excludes frames (e.g. those where the QP did not converge).
    """
    wrench_w = np.asarray(wrench_w, dtype=float)
    phase = np.asarray(phase)
    if rule.frames not in ("aided", "all"):
        raise ValueError(f"BoundRule.frames must be 'aided' or 'all', got '{rule.frames}'.")
    keep = np.ones(wrench_w.shape[0], dtype=bool)
    if valid is not None:
        keep &= np.asarray(valid, dtype=bool)  # never modify the caller's mask
    if rule.frames == "aided":
        keep &= np.linalg.norm(wrench_w, axis=1) > rule.unaided_tol
    wrench_w, phase = wrench_w[keep], phase[keep]
    if wrench_w.ndim != 2 or wrench_w.shape[1] != 6:
        raise ValueError(f"wrench_w must have shape (T, 6), got {wrench_w.shape}.")
    if phase.shape != (wrench_w.shape[0],):
        raise ValueError(f"phase must have shape ({wrench_w.shape[0]},), got {phase.shape}.")
    if rule.name != "percentile_margin":
        raise ValueError(f"Unknown bound rule '{rule.name}'; known: 'percentile_margin'.")
    if not 0.0 <= rule.percentile <= 100.0:
        raise ValueError(f"BoundRule.percentile must lie in [0, 100], got {rule.percentile}.")
    floor = np.array([rule.floor_force_n] * 3 + [rule.floor_torque_nm] * 3)
    eta0 = np.tile(floor, (num_phases, 1))
    for p in range(num_phases):
        rows = np.abs(wrench_w[phase == p])
        if rows.shape[0]:
            eta0[p] = np.maximum(floor, rule.margin * np.percentile(rows, rule.percentile, axis=0))
    return eta0


def envelope_per_phase(
    wrench_w: np.ndarray, phase: np.ndarray, num_phases: int, percentile: float = 95.0
) -> dict[str, np.ndarray]:
    """Per phase and axis: max, percentile and mean of |w| (each (num_phases, 6)), NaN if empty."""
    absw = np.abs(np.asarray(wrench_w, dtype=float))
    out = {k: np.full((num_phases, 6), np.nan) for k in ("max", f"p{percentile:g}", "mean")}
    for p in range(num_phases):
        rows = absw[np.asarray(phase) == p]
        if rows.shape[0]:
            out["max"][p] = rows.max(axis=0)
            out[f"p{percentile:g}"][p] = np.percentile(rows, percentile, axis=0)
            out["mean"][p] = rows.mean(axis=0)
    return out


def help_causes_per_phase(
    wrench_full_w: np.ndarray,
    wrench_novice_w: np.ndarray,
    missing_torque_nm: np.ndarray,
    phase: np.ndarray,
    phase_names: tuple[str, ...],
    joint_names: tuple[str, ...],
    lagging_tol_nm: float = 0.5,
) -> dict[str, dict]:
    """Per phase: what share of the novice's help comes from which cause (JSON-ready).

    Args:
        wrench_full_w: (T, 6) wrench at alpha = 1 [N, N m]: what the motion needs beyond what the
            contacts can give (flight, friction, centre of pressure), at full strength.
        wrench_novice_w: (T, 6) wrench of the novice [N, N m].
        missing_torque_nm: (T, 29) torque the novice's joints lack [N m]: where a limb
            lacks torque the pelvis cannot help, the limb lags instead.
        phase: (T,) phase ids; phase_names, joint_names: labels.
        lagging_tol_nm: |eps| above this counts as lagging [N m].

    Returns per phase name: ``motion_share`` (sum |w_full| / sum |w_novice|, capped at 1, the
    help the motion itself asks for), ``torque_deficit_share`` (1 - motion_share: help because the
    novice's joints are weaker), ``mean_help_norm`` [N, N m mixed], ``lagging_frame_share`` (frames
    where a joint lacks torque) and ``most_lagging_joint`` with its largest missing torque [N m].
    """
    full = np.linalg.norm(np.asarray(wrench_full_w, dtype=float), axis=1)
    novice = np.linalg.norm(np.asarray(wrench_novice_w, dtype=float), axis=1)
    lag = np.abs(np.asarray(missing_torque_nm, dtype=float))
    out = {}
    for p, name in enumerate(phase_names):
        rows = np.asarray(phase) == p
        if not np.any(rows):
            out[name] = None
            continue
        total = float(novice[rows].sum())
        motion = 1.0 if total <= 1e-9 else min(1.0, float(full[rows].sum()) / total)
        worst = lag[rows].max(axis=0)
        j = int(np.argmax(worst))
        out[name] = {
            "motion_share": motion,
            "torque_deficit_share": 1.0 - motion,
            "mean_help_norm": float(novice[rows].mean()),
            "lagging_frame_share": float(np.mean(lag[rows].max(axis=1) > lagging_tol_nm)),
            "most_lagging_joint": joint_names[j],
            "max_missing_torque_nm": float(worst[j]),
        }
    return out
