"""The wrench QP's result along a reference (:class:`WrenchProfile`): arrays only.

Apart from the solver (:mod:`optimal_control.wrench_qp`, which needs Pinocchio and proxsuite), so
that reading an oracle artifact (:mod:`optimal_control.artifact`) needs neither: the lent GPU
machine's image has none of them (docs/gpu.md, "A GPU visit").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class WrenchProfile:
    """The wrench QP solved along a reference (arrays of T frames)."""

    alpha: float  # torque-limit fraction used
    wrench_w: np.ndarray  # (T, 6) pelvis wrench [N, N m], world axes at the pelvis CoM
    contact_wrench_w: np.ndarray  # (T, 2, 6) sole wrenches [N, N m], world axes, sole origins
    corner_forces_w: np.ndarray  # (T, 2, 4, 3) corner forces [N]
    tau_nm: np.ndarray  # (T, 29) joint torques [N m]
    missing_torque_nm: np.ndarray  # (T, 29) eps: torque the joints lack to follow [N m]
    residual: np.ndarray  # (T,) dynamics residual [N or N m]
    solved: np.ndarray  # (T,) bool, the QP converged
    unaided: np.ndarray  # (T,) bool
    iterations: np.ndarray  # (T,) int
    warm_started: np.ndarray  # (T,) bool, answered by the warm start (False: by a retry)
    solve_time_s: np.ndarray  # (T,) [s]
    status: list[str] = field(default_factory=list)  # (T,) proxsuite status names

    @property
    def wrench_norm(self) -> np.ndarray:
        """(T,) Euclidean norm of the pelvis wrench [N, N m mixed]."""
        return np.linalg.norm(self.wrench_w, axis=1)

    def stats(self) -> dict:
        """Solver statistics: time per frame, iterations, residual, unaided fraction."""
        return {
            "alpha": self.alpha,
            "frames": int(self.wrench_w.shape[0]),
            "mean_time_ms": float(1e3 * self.solve_time_s.mean()),
            "max_time_ms": float(1e3 * self.solve_time_s.max()),
            "mean_iterations": float(self.iterations.mean()),
            "warm_start_retries": int(np.sum(~self.warm_started)),
            "max_residual": float(self.residual.max()),
            "solved_fraction": float(self.solved.mean()),
            "unaided_fraction": float(self.unaided.mean()),
            "max_wrench_norm": float(self.wrench_norm.max()),
            "max_missing_torque_nm": float(np.abs(self.missing_torque_nm).max()),
            "statuses": sorted(set(self.status)),
        }

    def to_arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """Arrays for an npz file, keys prefixed (e.g. ``alpha_0.50_``)."""
        return {
            f"{prefix}wrench_w": self.wrench_w,
            f"{prefix}contact_wrench_w": self.contact_wrench_w,
            f"{prefix}corner_forces_w": self.corner_forces_w,
            f"{prefix}tau_nm": self.tau_nm,
            f"{prefix}missing_torque_nm": self.missing_torque_nm,
            f"{prefix}residual": self.residual,
            f"{prefix}solved": self.solved,
            f"{prefix}unaided": self.unaided,
            f"{prefix}iterations": self.iterations,
            f"{prefix}warm_started": self.warm_started,
            f"{prefix}solve_time_s": self.solve_time_s,
        }
