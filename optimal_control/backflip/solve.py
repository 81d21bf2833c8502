"""Solve the backflip NLP with IPOPT: continuation on the wrench cost, warm starts, a cache."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from optimal_control.backflip.config import BackflipConfig
from optimal_control.backflip.sagittal import SagittalModel, sagittal_model_for
from optimal_control.backflip.transcription import (
    Solution,
    Transcription,
    build_transcription,
    initial_guess,
)
from optimal_control.files import atomic_save_npz, read_npz


@dataclass
class StageStats:
    """IPOPT statistics of one continuation stage."""

    wrench_weight: float  # pelvis wrench cost weight of this stage
    iterations: int  # IPOPT iterations
    wall_time_s: float  # wall time of the stage [s]
    return_status: str  # IPOPT return status
    success: bool  # IPOPT reported success
    objective: float  # final objective value
    refinement: int = 0  # 0: continuation stage; i > 0: i-th torque-bound refinement re-solve


@dataclass
class SolveResult:
    """Outcome of :func:`solve_backflip_to`."""

    solution: Solution
    transcription: Transcription
    stages: list[StageStats]
    build_time_s: float  # time to build the NLP and the solver [s]
    warm_started: bool  # started from a cached / given solution
    violations: dict[str, float] = field(default_factory=dict)  # group -> max violation
    # the cached solution of this very problem was checked and reused: no solver, no IPOPT
    reused_cached_solution: bool = False

    @property
    def success(self) -> bool:
        """All continuation stages converged and the constraints hold (a rejected torque
        refinement keeps the solution before it)."""
        return all(s.success for s in self.stages if not s.refinement) and self.max_violation < 1e-5

    @property
    def max_violation(self) -> float:
        """Largest constraint violation over all groups."""
        return max(self.violations.values(), default=0.0)

    @property
    def total_iterations(self) -> int:
        """IPOPT iterations over all stages."""
        return sum(s.iterations for s in self.stages)

    @property
    def solve_time_s(self) -> float:
        """IPOPT wall time over all stages [s]."""
        return sum(s.wall_time_s for s in self.stages)

    def stats_dict(self) -> dict:
        """JSON-friendly solver statistics."""
        return {
            "stages": [asdict(s) for s in self.stages],
            "build_time_s": self.build_time_s,
            "solve_time_s": self.solve_time_s,
            "total_iterations": self.total_iterations,
            "warm_started": self.warm_started,
            "reused_cached_solution": self.reused_cached_solution,
            "num_variables": int(self.transcription.nlp["x"].shape[0]),
            "num_constraints": int(self.transcription.nlp["g"].shape[0]),
            "max_violation": self.max_violation,
            "violations": self.violations,
            "success": self.success,
        }


class InfeasibleBackflipError(RuntimeError):
    """IPOPT ended without a feasible point; the message names the violated constraint groups."""

    def __init__(self, message: str, result: SolveResult, saved_to: Path | None) -> None:
        super().__init__(message)
        self.result = result
        self.saved_to = saved_to


def constraint_violations(tr: Transcription, x: np.ndarray, g: np.ndarray) -> dict[str, float]:
    """Max violation of each constraint group (and of the variable bounds) at (x, g)."""
    out = {}
    for name, a, b in tr.groups:
        viol = np.maximum(tr.lbg[a:b] - g[a:b], 0.0) + np.maximum(g[a:b] - tr.ubg[a:b], 0.0)
        out[name] = float(viol.max()) if b > a else 0.0
    bound = np.maximum(tr.lbx - x, 0.0) + np.maximum(x - tr.ubx, 0.0)
    out["variable bounds (joint limits, speeds, wrench, durations)"] = float(bound.max())
    return out


TORQUE_REFINE_TARGET = 5e-4
"""Refinement goal: the 1 kHz torque stays within (1 + this) x the TO's torque bound."""


def torque_overshoot(tr: Transcription, sol: Solution, model: SagittalModel) -> np.ndarray:
    """(N, 29) largest excess of the 1 kHz interpolant's |tau| over the TO's torque bound
    (alpha x tau_max, held joints their fraction; margin not included) in each interval, as a
    fraction of tau_max (<= 0 where within)."""
    from optimal_control.backflip.trajectory import sample_solution

    grid = tr.grid
    flip = sample_solution(sol, grid, model, 1000.0)
    t_knots = sol.knot_times_s(grid)
    k = np.clip(np.searchsorted(t_knots, flip.time_s, side="right") - 1, 0, grid.num_intervals - 1)
    ratio = np.abs(flip.tau_nm) / model.effort_limit_nm - tr.torque_limit_fraction
    out = np.full((grid.num_intervals, ratio.shape[1]), -np.inf)
    np.maximum.at(out, k, ratio)
    return out


def refine_torque_bounds(
    tr: Transcription, lbg: np.ndarray, ubg: np.ndarray, overshoot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Tighten the torque rows of the samples (knots at both ends, midpoint) of every interval
    whose interpolant overshoots the bound, by twice the overshoot (+ the refinement target) on
    the overshooting joints. Returns the new (lbg, ubg) and the number of (interval, joint) pairs."""
    rows_g = _torque_rows(tr)
    nj = overshoot.shape[1]
    lo = lbg[rows_g].reshape(-1, nj).copy()
    hi = ubg[rows_g].reshape(-1, nj).copy()
    u = tr.torque_sample_u
    bad = overshoot > TORQUE_REFINE_TARGET * np.maximum(tr.torque_limit_fraction, 1e-9)
    for k, j in zip(*np.nonzero(bad), strict=True):
        rows = (u >= k) & (u <= k + 1)
        # twice the overshoot: the peak between the samples moves with their bound, but less
        cut = 2.0 * overshoot[k, j] + TORQUE_REFINE_TARGET * tr.torque_limit_fraction[j]
        hi[rows, j] = np.maximum(hi[rows, j] - cut, 0.0)
        lo[rows, j] = np.minimum(lo[rows, j] + cut, 0.0)
    lbg, ubg = lbg.copy(), ubg.copy()
    lbg[rows_g], ubg[rows_g] = lo.ravel(), hi.ravel()
    return lbg, ubg, int(bad.sum())


def _torque_rows(tr: Transcription) -> slice:
    _, start, stop = next(g for g in tr.groups if g[0].startswith("torque limits"))
    return slice(start, stop)


def torque_cut(tr: Transcription, ubg: np.ndarray) -> np.ndarray:
    """(blocks, 29) tightening of the torque rows in ``ubg`` against the transcription's own."""
    rows = _torque_rows(tr)
    return (tr.ubg[rows] - ubg[rows]).reshape(len(tr.torque_sample_u), -1)


def apply_torque_cut(tr: Transcription, cut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lbg, ubg) of ``tr`` with the torque rows tightened by ``cut`` (see :func:`torque_cut`)."""
    rows = _torque_rows(tr)
    lbg, ubg = tr.lbg.copy(), tr.ubg.copy()
    ubg[rows] = np.maximum(ubg[rows] - cut.ravel(), 0.0)
    lbg[rows] = np.minimum(lbg[rows] + cut.ravel(), 0.0)
    return lbg, ubg


def _problem_source_digest() -> str:
    """Digest of the code that defines the NLP, so a cached solution of an older transcription
    is never taken for the current problem's."""
    here = Path(__file__).resolve().parent
    nlp_modules = ("config.py", "sagittal.py", "transcription.py", "solve.py")
    files = [here / name for name in nlp_modules] + [here.parent / "casadi_dynamics.py"]
    digest = hashlib.sha1()
    for path in files:
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _robot_digest() -> str:
    """Digest of the robot description the NLP is built from (URDF, armature table)."""
    from robots.assets import g1_urdf_path

    here = Path(__file__).resolve().parents[2]
    digest = hashlib.sha1(g1_urdf_path().read_bytes())
    digest.update((here / "robots" / "g1.py").read_bytes())
    return digest.hexdigest()


def problem_key(cfg: BackflipConfig) -> str:
    """Full hash (40 hex digits) of everything that defines the problem and its solution: the
    config fields that change the NLP (not solver or I/O options), the code that builds it, the
    robot description and the CasADi (IPOPT) version."""
    skip = {"max_iter", "tol", "print_level", "warm_start", "cache_dir", "hessian"}
    data = {k: v for k, v in asdict(cfg).items() if k not in skip}
    data["_source"] = _problem_source_digest()
    data["_robot"] = _robot_digest()
    data["_casadi"] = ca.__version__
    return hashlib.sha1(json.dumps(data, sort_keys=True).encode()).hexdigest()


def config_key(cfg: BackflipConfig) -> str:
    """Short form of :func:`problem_key`, used in cache file names."""
    return problem_key(cfg)[:12]


def _solver(tr: Transcription, cfg: BackflipConfig) -> ca.Function:
    # a smaller initial barrier (mu_init 1e-3 or 1e-5) for warm starts was tried: no fewer
    # iterations (85 either way on the full flip), so IPOPT's defaults are kept
    opts = {
        "expand": cfg.symbolic == "SX",
        "print_time": False,
        "ipopt": {
            "print_level": cfg.print_level,
            "max_iter": cfg.max_iter,
            "tol": cfg.tol,
            "acceptable_tol": 1e-4,
            "constr_viol_tol": 1e-6,
            "mu_strategy": "adaptive",
            "linear_solver": "mumps",
            "hessian_approximation": cfg.hessian,
            "sb": "yes",
        },
    }
    return ca.nlpsol("backflip", "ipopt", tr.nlp, opts)


def solve_backflip_to(
    cfg: BackflipConfig,
    model: SagittalModel | None = None,
    warm_start: Solution | None = None,
    raise_on_failure: bool = True,
    failure_path: Path | None = None,
) -> SolveResult:
    """Solve the backflip TO of ``cfg``.

    Cold start: the hand-designed guess of :func:`initial_guess`, then one IPOPT solve per entry of
    ``cfg.wrench_weights`` (cheap wrench first, so the first stage only has to find a kinematically
    sound flip; each later stage starts from the previous one and pushes the help to zero where the
    robot can do without). Warm start (``warm_start`` or ``cfg.warm_start`` path): only the last
    weight is solved, with the warm start's ``torque_cut`` re-applied.

    Then up to ``cfg.torque_refinements`` warm re-solves of the last stage with the same solver:
    where the 1 kHz interpolant's torque exceeds the bound between the knot and midpoint samples
    (:func:`torque_overshoot`), those samples' bounds are tightened (:func:`refine_torque_bounds`);
    the total tightening is returned as ``solution.torque_cut``.

    If the last stage ends infeasible and ``raise_on_failure``, the last iterate is saved to
    ``failure_path`` (if given) and :class:`InfeasibleBackflipError` names the violated groups.
    """
    cfg.validate()
    if warm_start is None and cfg.warm_start:  # read before the (slow) NLP build
        warm_start = load_solution(Path(cfg.warm_start).expanduser(), "--warm-start solution")
    model = model or sagittal_model_for(cfg)
    t0 = time.perf_counter()
    tr = build_transcription(model, cfg)
    weights = list(cfg.wrench_weights)
    if warm_start is not None:
        if warm_start.r.shape[0] != tr.grid.num_knots:
            raise ValueError(
                f"Warm start has {warm_start.r.shape[0]} knots, the problem {tr.grid.num_knots}: "
                "use a solution of the same phase intervals."
            )
        guess, weights = warm_start, weights[-1:]
    else:
        guess = initial_guess(model, cfg)
    solver = _solver(tr, cfg)
    build_time = time.perf_counter() - t0
    x = np.clip(tr.pack(guess), tr.lbx, tr.ubx)
    stages: list[StageStats] = []
    lam_x = lam_g = None
    g = np.zeros(tr.lbg.shape)
    lbg, ubg = tr.lbg, tr.ubg
    cut0 = None if warm_start is None else warm_start.torque_cut
    if cut0 is not None and cut0.shape == (len(tr.torque_sample_u), len(model.effort_limit_nm)):
        lbg, ubg = apply_torque_cut(tr, cut0)  # the warm start's refined problem
    # continuation stages, then re-solves of the last one with the torque bounds tightened where
    # the interpolant overshoots between the knot and midpoint samples (bounds are solver inputs:
    # no rebuild)
    plan = [(w, 0) for w in weights] + [
        (weights[-1], i + 1) for i in range(max(cfg.torque_refinements, 0))
    ]
    for weight, refinement in plan:
        if refinement:
            if not all(s.success for s in stages):
                break  # refine a solution, not a failed iterate
            overshoot = torque_overshoot(tr, tr.solution(x), model)
            kept = (lbg, ubg)
            lbg, ubg, count = refine_torque_bounds(tr, lbg, ubg, overshoot)
            if count == 0:
                break
        args = {"x0": x, "lbx": tr.lbx, "ubx": tr.ubx, "lbg": lbg, "ubg": ubg, "p": weight}
        if lam_g is not None:
            args.update(lam_x0=lam_x, lam_g0=lam_g)
        t1 = time.perf_counter()
        out = solver(**args)
        wall = time.perf_counter() - t1
        st = solver.stats()
        stage = StageStats(
            float(weight),
            int(st.get("iter_count", -1)),
            wall,
            str(st.get("return_status", "")),
            bool(st.get("success", False)),
            float(out["f"]),
            refinement,
        )
        stages.append(stage)
        if refinement and not stage.success:
            stage.return_status += " (refinement rejected: the solution before it is kept)"
            lbg, ubg = kept
            break
        x = np.asarray(out["x"]).ravel()
        g = np.asarray(out["g"]).ravel()
        lam_x, lam_g = out["lam_x"], out["lam_g"]
    solution = tr.solution(x)
    cut = torque_cut(tr, ubg)
    solution.torque_cut = cut if np.any(cut != 0.0) else None
    result = SolveResult(
        solution,
        tr,
        stages,
        build_time,
        warm_start is not None,
        constraint_violations(tr, x, g),
    )
    if raise_on_failure and result.max_violation > 1e-4:
        saved = None
        if failure_path is not None:
            saved = save_solution(result.solution, failure_path)
        bad = {k: v for k, v in result.violations.items() if v > 1e-4}
        lines = "\n".join(
            f"  - {k}: max violation {v:.3g}" for k, v in sorted(bad.items(), key=lambda kv: -kv[1])
        )
        raise InfeasibleBackflipError(
            f"The backflip TO found no feasible motion (IPOPT: {stages[-1].return_status}). "
            f"Violated constraint groups:\n{lines}\n"
            + (f"Last iterate saved to {saved}. " if saved else "")
            + "Allow the pelvis wrench (no --forbid-wrench), raise --torque-scale or widen the "
            "phase duration bounds.",
            result,
            saved,
        )
    return result


def cache_path(cfg: BackflipConfig) -> Path:
    """Where the solution of ``cfg`` is cached for warm starts."""
    return Path(cfg.cache_dir).expanduser() / f"backflip_{config_key(cfg)}.npz"


def save_solution(sol: Solution, path: Path, cfg: BackflipConfig | None = None) -> Path:
    """Write a solution as npz (for warm starts), atomically. With ``cfg`` (the solution cache),
    the file also holds the full :func:`problem_key` and the IPOPT tolerance it was solved to,
    which :func:`load_cached_solution` checks."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = sol.to_npz_dict()
    if cfg is not None:
        arrays |= {
            CACHE_KEY_ARRAY: np.array(problem_key(cfg)),
            CACHE_TOL_ARRAY: np.array(float(cfg.tol)),
        }
    return atomic_save_npz(path, arrays, compressed=False)


CACHE_KEY_ARRAY = "cache_problem_key"
"""Array of a cache file holding the :func:`problem_key` it was solved for."""
CACHE_TOL_ARRAY = "cache_ipopt_tol"
"""Array of a cache file holding the IPOPT tolerance it was solved to."""


class StaleCacheError(ValueError):
    """A cache file is a valid solution, but of another problem (or one solved less tightly)."""


def load_solution(path: Path, what: str) -> Solution:
    """Read a solution written by :func:`save_solution`; ``what`` names it in errors.

    Raises :class:`ValueError` (junk, truncated, missing arrays, non-finite values) or
    :class:`FileNotFoundError`, naming the file.
    """
    return _load_solution_arrays(path, what)[0]


def _load_solution_arrays(path: Path, what: str) -> tuple[Solution, dict]:
    arrays = read_npz(path, what)
    try:
        sol = Solution.from_npz(arrays)
    except (KeyError, ValueError, TypeError, IndexError) as err:
        raise ValueError(
            f"{what} '{path}' is not a backflip solution (arrays {sorted(arrays)}; {err!r}); "
            "pass a solution.npz written by solve-backflip."
        ) from err
    for name, value in arrays.items():
        if np.issubdtype(value.dtype, np.number) and not np.all(np.isfinite(value)):
            raise ValueError(f"{what} '{path}': array '{name}' has NaN/inf; pass another file.")
    return sol, arrays


def load_cached_solution(path: Path, cfg: BackflipConfig) -> Solution:
    """Read the cache file of ``cfg`` and check that it was solved for this very problem.

    Raises :class:`ValueError` if the file is not a solution (corrupt) and
    :class:`StaleCacheError` if its stored :func:`problem_key` is missing or differs (a file of
    an older code, robot or CasADi, or a file name collision) or it was solved to a looser
    tolerance than ``cfg.tol``.
    """
    sol, arrays = _load_solution_arrays(path, "backflip cache file")
    key = arrays.get(CACHE_KEY_ARRAY)
    tol = arrays.get(CACHE_TOL_ARRAY)
    if key is None or key.dtype.kind != "U" or str(key) != problem_key(cfg):
        raise StaleCacheError(
            f"backflip cache file '{path}' was solved for another problem (stored key "
            f"{None if key is None else str(key)[:12]}, this problem {config_key(cfg)})."
        )
    if tol is None or not float(tol) <= cfg.tol:
        raise StaleCacheError(
            f"backflip cache file '{path}' was solved to IPOPT tol "
            f"{None if tol is None else float(tol):.3g}, looser than the asked {cfg.tol:.3g}."
        )
    return sol


REUSE_VIOLATION_TOL = 1e-6
"""A cached solution is reused only if it meets every constraint of the rebuilt problem (with
its torque cut) to this (IPOPT's ``constr_viol_tol``)."""


def reuse_solution(
    cfg: BackflipConfig, sol: Solution, model: SagittalModel | None = None
) -> SolveResult | None:
    """The :class:`SolveResult` of a cached solution of ``cfg``'s problem, without a solver.

    The cache file holds the solution IPOPT converged to for exactly this NLP (same
    :func:`problem_key`, at least as tight a tolerance) and its torque cut; re-solving it (after
    the exact-Hessian solver's build; its cost: ``docs/backflip.md``) returns it again to solver
    tolerance. Here the NLP's constraint functions alone are built (no
    derivatives) and evaluated at the solution: it is returned if every constraint, with the
    cut re-applied, holds to :data:`REUSE_VIOLATION_TOL`; otherwise None (re-solve it).
    """
    cfg.validate()
    model = model or sagittal_model_for(cfg)
    t0 = time.perf_counter()
    tr = build_transcription(model, cfg)
    if sol.r.shape[0] != tr.grid.num_knots:
        return None
    g_fn = ca.Function("backflip_g", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["g"]])
    x = tr.pack(sol)
    g = np.asarray(g_fn(x, cfg.wrench_weights[-1])).ravel()
    build_time = time.perf_counter() - t0
    nj = len(model.effort_limit_nm)
    cut = sol.torque_cut
    if cut is not None and cut.shape == (len(tr.torque_sample_u), nj):
        lbg, ubg = apply_torque_cut(tr, cut)
    elif cut is None:
        lbg, ubg = tr.lbg, tr.ubg
    else:
        return None
    strict = constraint_violations(dataclasses.replace(tr, lbg=lbg, ubg=ubg), x, g)
    if max(strict.values(), default=0.0) > REUSE_VIOLATION_TOL:
        return None
    return SolveResult(
        sol, tr, [], build_time, True, constraint_violations(tr, x, g), reused_cached_solution=True
    )
