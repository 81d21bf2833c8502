"""Comparison of training runs (``a2cf-mb compare RUN...``): one figure and one table.

Per run folder it reads ``config.json`` (task, mode, sizes, reward weights), ``metrics.json``
(per-iteration rows: env steps, mean step reward, applied force, bound norm, assist switch), the
TensorBoard events (``Curriculum/terrain_level``, ``Reward/<tracking term>``) and ``eval.json``
when an evaluation ran.

Figure (like the paper's walking figure): terrain level (skill progress for tasks without a
terrain curriculum), force bound |eta|, total step reward and the raw velocity-tracking reward
(in [0, 1]: the logged term over its weight and the step dt), each against iterations (top row)
and env steps (bottom row). Table: iterations and env steps to each given level, to negligible
force (assistance switched off, 0.1 N by default), final tracking error with assistance off.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from optimal_control.files import atomic_savefig, atomic_write_json
from rl.runs.folder import (
    EVAL_FILE,
    EVENTS_GLOB,
    METRICS_FILE,
    DamagedRunFileError,
    read_config_file,
    read_run_json,
)
from robots.mujoco_model import MujocoModelConfig

TRACKING_TERMS = ("track_lin_vel_xy", "track_ang_vel_z")
"""Reward terms whose raw value is plotted as the tracking reward (when the task has them)."""


@dataclass(frozen=True)
class CompareConfig:
    """Where the comparison goes and which thresholds its table reports."""

    out: str = "."  # folder receiving compare.png and compare.json
    levels: tuple[float, ...] = (1.0, 2.0, 3.0)  # terrain levels whose first crossing counts [-]
    negligible_force_n: float = 0.1  # applied force counted as negligible (paper: 0.1 N) [N]


COMPARE_PLOT = "compare.png"
COMPARE_JSON = "compare.json"


def _scalars(run_dir: Path) -> dict[str, np.ndarray]:
    """TensorBoard scalars of a run: tag -> (steps, values) stacked as a (K, 2) array."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = sorted(run_dir.glob(EVENTS_GLOB))
    out: dict[str, np.ndarray] = {}
    for path in events:
        acc = EventAccumulator(str(path), size_guidance={"scalars": 0})
        acc.Reload()
        for tag in acc.Tags()["scalars"]:
            rows = np.array([(e.step, e.value) for e in acc.Scalars(tag)], dtype=float)
            out[tag] = np.concatenate([out[tag], rows]) if tag in out else rows
    for tag, rows in out.items():  # a resumed run may repeat steps: keep the last value
        _, last = np.unique(rows[::-1, 0], return_index=True)
        out[tag] = rows[::-1][last]
    return out


def load_run(run_dir: str | Path) -> dict[str, Any]:
    """The curves of one run folder, per iteration (see the module docstring)."""
    run_dir = Path(run_dir)
    metrics_path = run_dir / METRICS_FILE
    config = read_config_file(run_dir, sections=("train", "task", "env"))
    if not metrics_path.is_file():
        raise FileNotFoundError(
            f"{metrics_path} not found: '{run_dir}' is not a finished run (metrics.json is "
            f"written when training ends); finish it, or write it again, with `a2cf-mb train "
            f"--resume {run_dir}` (a finished run only exports)"
        )
    metrics = read_run_json(
        metrics_path, "the run's metrics", f"write it again with `a2cf-mb train --resume {run_dir}`"
    )
    if not isinstance(metrics, dict) or not isinstance(metrics.get("iterations"), list):
        raise DamagedRunFileError(
            f"{metrics_path} has no 'iterations' list: write it again with `a2cf-mb train "
            f"--resume {run_dir}`"
        )
    rows = metrics["iterations"]
    if not rows:
        raise ValueError(f"{metrics_path} has no iterations: nothing to compare")
    iterations = np.array([r["iteration"] for r in rows], dtype=float)
    env_steps = np.cumsum([r["env_steps"] for r in rows]).astype(float)
    scalars = _scalars(run_dir)
    logged = max((int(v[:, 0].max()) for v in scalars.values() if len(v)), default=-1)
    if logged < iterations[-1]:  # a damaged or missing TensorBoard file: say so, not silently
        where = f"end at iteration {logged}" if logged >= 0 else "hold no readable scalar"
        warnings.warn(
            f"the TensorBoard files of {run_dir} {where}, its metrics at "
            f"{int(iterations[-1])}: they are damaged or missing, so the curves read from them "
            "(terrain level, tracking terms) stop there",
            stacklevel=2,
        )
    dt_s = MujocoModelConfig().timestep_s * config["env"]["decimation"]
    weights = {t["name"]: t["weight"] for t in config["task"]["rewards"]}

    def per_iteration(tag: str) -> np.ndarray | None:
        if tag not in scalars:
            return None
        steps, values = scalars[tag][:, 0], scalars[tag][:, 1]
        return np.interp(iterations, steps, values)

    level = per_iteration("Curriculum/terrain_level")
    tracking = {
        name: per_iteration(f"Reward/{name}") / (weights[name] * dt_s)
        for name in TRACKING_TERMS
        if name in weights and f"Reward/{name}" in scalars and weights[name] != 0
    }
    eta_norm = np.array([r["eta_norm"][0] if r.get("eta_norm") else 0.0 for r in rows], dtype=float)
    assist = np.array([bool(r.get("assist_enabled")) for r in rows])
    eval_path = run_dir / EVAL_FILE
    return {
        "run_dir": str(run_dir),
        "label": f"{config['train']['mode']} ({run_dir.name})",
        "mode": config["train"]["mode"],
        "task": config["train"]["task"],
        "iterations": iterations,
        "env_steps": env_steps,
        "terrain_level": level,
        "skill_progress": np.array([r.get("skill_progress") or 0.0 for r in rows], dtype=float),
        "eta_norm": eta_norm,
        "applied_force_n": np.array([r.get("applied_force_n") or 0.0 for r in rows], dtype=float),
        "assist_enabled": assist,
        "mean_step_reward": np.array([r.get("mean_step_reward") or 0.0 for r in rows], dtype=float),
        "tracking": tracking,
        "eval": read_run_json(
            eval_path, "the result of `a2cf-mb eval`", f"run `a2cf-mb eval {run_dir}` again"
        )
        if eval_path.is_file()
        else None,
    }


def _first_crossing(x: np.ndarray, curve: np.ndarray | None, value: float) -> float | None:
    """First ``x`` at which ``curve`` reaches ``value`` (None: never)."""
    if curve is None:
        return None
    hit = np.flatnonzero(curve >= value)
    return float(x[hit[0]]) if hit.size else None


def summarise_run(run: dict[str, Any], levels: tuple[float, ...], negligible_force_n: float):
    """Table row of one loaded run."""
    level_curve = run["terrain_level"]
    row: dict[str, Any] = {
        "run": run["label"],
        "mode": run["mode"],
        "iterations_done": int(run["iterations"][-1]) + 1,
        "env_steps_done": float(run["env_steps"][-1]),
        "final_terrain_level": float(level_curve[-1]) if level_curve is not None else None,
        "max_terrain_level": float(level_curve.max()) if level_curve is not None else None,
        "final_mean_step_reward": float(run["mean_step_reward"][-1]),
        "final_skill_progress": float(run["skill_progress"][-1]),
        "to_level": {},
    }
    for level in levels:
        it = _first_crossing(run["iterations"], level_curve, level)
        steps = _first_crossing(run["env_steps"], level_curve, level)
        row["to_level"][str(level)] = {"iterations": it, "env_steps": steps}
    # Negligible force: assistance switched off by Algorithm 1 (never for the baseline).
    off = np.flatnonzero(~run["assist_enabled"]) if run["mode"] != "baseline" else np.array([])
    below = np.flatnonzero((run["applied_force_n"] < negligible_force_n) & (run["eta_norm"] > 0))
    first = off[0] if off.size else (below[0] if below.size else None)
    row["to_negligible_force"] = (
        {"iterations": float(run["iterations"][first]), "env_steps": float(run["env_steps"][first])}
        if first is not None
        else None
    )
    for name, curve in run["tracking"].items():
        row[f"final_raw_{name}"] = float(curve[-1])
    ev = run["eval"]
    if ev is not None:
        metrics = ev.get("task_metrics") or {}
        row["eval_survival"] = ev.get("survival_fraction")
        row["eval_lin_vel_error_mps"] = metrics.get("lin_vel_error_mps")
        row["eval_yaw_rate_error_rps"] = metrics.get("yaw_rate_error_rps")
    return row


def compare_runs(
    run_dirs: list[str | Path],
    out_dir: str | Path,
    levels: tuple[float, ...] = (1.0, 2.0, 3.0),
    negligible_force_n: float = 0.1,
) -> dict[str, Any]:
    """Load the runs, write ``compare.png`` and ``compare.json`` into ``out_dir``; the table."""
    if not run_dirs:
        raise ValueError("compare needs at least one run folder")
    runs = [load_run(d) for d in run_dirs]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    table = [summarise_run(r, tuple(levels), negligible_force_n) for r in runs]
    plot_runs(runs, out_dir / COMPARE_PLOT)
    result = {
        "runs": table,
        "levels": list(levels),
        "negligible_force_n": negligible_force_n,
        "plot": str(out_dir / COMPARE_PLOT),
    }
    atomic_write_json(out_dir / COMPARE_JSON, result)
    return result


def plot_runs(runs: list[dict[str, Any]], path: Path) -> None:
    """The 2 x 4 comparison figure (rows: against iterations, against env steps)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    has_level = all(r["terrain_level"] is not None for r in runs)
    panels = (
        ("terrain_level" if has_level else "skill_progress",
         "terrain level [-]" if has_level else "skill progress [-]"),
        ("eta_norm", "force bound |eta| [N, Nm]"),
        ("mean_step_reward", "total step reward [-]"),
        ("tracking", "raw lin. vel. tracking [0-1]"),
    )  # fmt: skip
    fig, axes = plt.subplots(2, len(panels), figsize=(18, 7))
    for run in runs:
        for row, xkey in enumerate(("iterations", "env_steps")):
            x = run[xkey]
            for ax, (key, _) in zip(axes[row], panels, strict=True):
                y = run["tracking"].get(TRACKING_TERMS[0]) if key == "tracking" else run[key]
                if y is None:
                    continue
                (line,) = ax.plot(x, y, label=run["label"])
                off = np.flatnonzero(~run["assist_enabled"])
                if run["mode"] != "baseline" and off.size:
                    ax.axvline(x[off[0]], color=line.get_color(), ls="--", lw=0.8)
    for row, xlabel in enumerate(("iteration", "env steps")):
        for ax, (_, ylabel) in zip(axes[row], panels, strict=True):
            ax.set_xlabel(xlabel)
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle("training comparison (dashed: assistance switched off)")
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=100)
    plt.close(fig)


def format_table(result: dict[str, Any]) -> str:
    """The comparison table as text."""
    lines = []
    for row in result["runs"]:
        lines.append(
            f"{row['run']}: {row['iterations_done']} it, {row['env_steps_done']:.0f} env steps, "
            f"final level {row['final_terrain_level']}, max level {row['max_terrain_level']}, "
            f"final step reward {row['final_mean_step_reward']:.4f}"
        )
        for level, hit in row["to_level"].items():
            lines.append(
                f"  to level {level}: iterations {hit['iterations']}, env steps {hit['env_steps']}"
            )
        lines.append(f"  to negligible force: {row['to_negligible_force']}")
        for key in sorted(k for k in row if k.startswith(("final_raw_", "eval_"))):
            lines.append(f"  {key}: {row[key]}")
    lines.append(f"figure: {result['plot']}")
    return "\n".join(lines)
