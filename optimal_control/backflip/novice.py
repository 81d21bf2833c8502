"""The explicit novice model of the backflip, and eta0 against the paper's hand-set table.

A free TO finds a motion the robot can do unaided whenever one exists, so its own least wrench
(zero at alpha = 1 here) says nothing about how much help a *learner* needs. The help is measured
against the solved flip held fixed as a reference:

1. **Torque-limited follower** (the oracle's per-frame QP, :mod:`optimal_control.wrench_qp`):
   the least pelvis wrench with which the G1 follows the solved reference when its joint torques
   are limited to alpha x effort limit, for alpha in the sweep (1, 0.5, 0.3). alpha = 0.5 (the
   rule's ``novice_alpha``) sets eta0. The upper envelope is the no-contact wrench (soles off,
   alpha = 1): the help that replaces the ground altogether (alpha = 0 is infeasible: a pelvis
   wrench cannot hold passive limbs).
2. **Take-off momentum deficit**: a novice whose push-off reaches only the fraction alpha of the
   solved take-off momentum must be made up for in the Air phase: a constant pelvis pitch torque
   (1 - alpha) L_y / T_air and vertical force (1 - alpha) m v_z / T_air (CoM angular momentum L_y
   and CoM vertical speed v_z at take-off, flight time T_air).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from optimal_control.bounds import AXIS_NAMES, PAPER_ETA0

NOVICE_MODEL = (
    "per-frame wrench QP along the solved TO backflip (50 Hz) with joint torques limited to "
    "alpha x effort limit (alpha swept; eta0 from the rule's novice alpha); upper envelope: "
    "no-contact wrench (soles off, alpha = 1); plus the take-off momentum deficit "
    "(1 - alpha) x take-off momentum spread over the flight"
)


def takeoff_momentum(robot_model: pin.Model, q: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """CoM linear momentum [kg m/s] and angular momentum about the CoM [kg m^2/s], world axes."""
    data = robot_model.createData()
    h = pin.computeCentroidalMomentum(robot_model, data, q, v)
    return {
        "linear_x": float(h.linear[0]),
        "linear_z": float(h.linear[2]),
        "angular_y": float(h.angular[1]),
    }


def momentum_deficit_wrench(
    momentum: dict[str, float], flight_time_s: float, alphas: tuple[float, ...]
) -> dict[str, dict[str, float]]:
    """Constant Air-phase pelvis help (fz [N], my [N m]) making up (1 - alpha) of the momentum."""
    out = {}
    for alpha in alphas:
        miss = 1.0 - alpha
        out[f"{alpha:.2f}"] = {
            "fz_n": miss * momentum["linear_z"] / flight_time_s,
            "my_nm": miss * abs(momentum["angular_y"]) / flight_time_s,
        }
    return out


def _high_phases(rows: np.ndarray, names: tuple[str, ...]) -> list[str]:
    """Phases whose bound is more than twice the axis' smallest bound."""
    low = rows.min()
    return [names[p] for p in range(len(rows)) if rows[p] > 2.0 * low + 1e-9]


def compare_with_paper(eta0: np.ndarray, phase_names: tuple[str, ...]) -> dict:
    """eta0 (5, 6) against the paper's table: values, and whether the pattern matches.

    Per axis, the "raised" phases are those whose bound is more than twice the axis' smallest
    bound; the paper raises fz (10 -> 100 N) and mz (10 -> 30 N m) in Jump and Air and keeps the
    other axes flat. The patterns match on an axis when the raised phases are the same.
    """
    paper = np.asarray(PAPER_ETA0["backflip"]["all"])
    axes = {}
    for i, axis in enumerate(AXIS_NAMES):
        paper_high = _high_phases(paper[:, i], phase_names)
        oracle_high = _high_phases(eta0[:, i], phase_names)
        axes[axis] = {
            "paper_raised": paper_high,
            "oracle_raised": oracle_high,
            "same_pattern": paper_high == oracle_high,
        }
    rows = []
    for p, name in enumerate(phase_names):
        rows.append({"phase": name, "oracle": eta0[p].tolist(), "paper": paper[p].tolist()})
    return {"rows": rows, "axes": axes}


def comparison_markdown(cmp: dict) -> str:
    """The comparison as a Markdown table (oracle / paper per axis)."""
    head = "| phase | " + " | ".join(f"{a} oracle / paper" for a in AXIS_NAMES) + " |"
    sep = "|---" * (len(AXIS_NAMES) + 1) + "|"
    lines = [head, sep]
    for row in cmp["rows"]:
        cells = [f"{o:.1f} / {p:.0f}" for o, p in zip(row["oracle"], row["paper"], strict=True)]
        lines.append(f"| {row['phase']} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("| axis | raised by the paper | raised by the oracle | same pattern |")
    lines.append("|---|---|---|---|")
    for axis, v in cmp["axes"].items():
        paper = ", ".join(v["paper_raised"]) or "none (flat)"
        oracle = ", ".join(v["oracle_raised"]) or "none (flat)"
        lines.append(f"| {axis} | {paper} | {oracle} | {'yes' if v['same_pattern'] else 'no'} |")
    return "\n".join(lines)
