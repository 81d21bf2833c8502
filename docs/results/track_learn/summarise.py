"""Summarise the track_learn runs: per run the curve of its policy alone (survival, tracking score,
joint error beside the statue's), where the target first held at two consecutive evaluations,
the 128-env confirmations (evals_checkpoints.jsonl), the seed spread per budget the demo reads,
and a figure.

Usage: python docs/results/track_learn/summarise.py RUN_DIR... --out docs/results/track_learn
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from optimal_control.files import atomic_savefig, atomic_write_json


def _rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _row(r: dict) -> dict:
    m = r.get("task_metrics", {})
    return {
        "iteration": r["iteration"],
        "env_steps": r["env_steps"],
        "num_envs": r["num_envs"],
        "survival": r["survival_fraction"],
        "tracking_score": m.get("tracking_score"),
        "joint_error_rad": m.get("joint_error_rad"),
        "statue_joint_error_rad": m.get("statue_joint_error_rad"),
        "pelvis_pos_error_m": m.get("pelvis_pos_error_m"),
        "pelvis_rot_error_rad": m.get("pelvis_rot_error_rad"),
        "target_reached": r["target_reached"],
    }


def summarise_run(run: Path) -> dict:
    """One run's curve, first target held twice, and confirmations."""
    curve = [_row(r) for r in _rows(run / "evals.jsonl")]
    held = next(
        (
            b
            for a, b in zip(curve[:-1], curve[1:], strict=True)
            if a["target_reached"] and b["target_reached"]
        ),
        None,
    )
    confirmations = [
        _row(r) for r in _rows(run / "evals_checkpoints.jsonl") if r["num_envs"] >= 128
    ]
    return {
        "run": run.name,
        "evaluations": len(curve),
        "env_steps_last": curve[-1]["env_steps"] if curve else 0,
        "target_held_twice_at": held,
        "confirmations_128": confirmations,
        "curve": curve,
    }


def seed_spread(runs: list[dict]) -> list[dict]:
    """At every evaluation iteration all runs share: the tracking score per run."""
    by_it = [{r["iteration"]: r for r in run["curve"]} for run in runs]
    common = sorted(set.intersection(*(set(b) for b in by_it))) if by_it else []
    return [
        {
            "iteration": it,
            "env_steps": by_it[0][it]["env_steps"],
            "metric": "tracking_score",
            "values": {
                run["run"]: b[it]["tracking_score"] for run, b in zip(runs, by_it, strict=True)
            },
        }
        for it in common
    ]


def plot(runs: list[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.4))
    axes = fig.subplots(1, 3)
    for run in runs:
        x = [r["env_steps"] / 1e6 for r in run["curve"]]
        axes[0].plot(x, [r["survival"] for r in run["curve"]], label=run["run"])
        axes[1].plot(x, [r["tracking_score"] for r in run["curve"]], label=run["run"])
        (line,) = axes[2].plot(x, [r["joint_error_rad"] for r in run["curve"]], label=run["run"])
        axes[2].plot(x, [r["statue_joint_error_rad"] for r in run["curve"]], ls=":",
                     color=line.get_color())  # fmt: skip
    axes[0].axhline(0.9, color="k", ls="--", lw=0.8)
    axes[1].axhline(1.0, color="k", ls="--", lw=0.8)
    axes[2].axhline(0.16, color="k", ls="--", lw=0.8)
    axes[1].set_yscale("log")
    for ax, title in zip(axes, ("survival alone", "tracking score (<= 1)",
                                "joint error [rad] (dotted: statue)"), strict=True):  # fmt: skip
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("env steps [M]")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    runs = [summarise_run(r) for r in args.runs]
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / "summary.json", {"runs": runs})
    spread = {"source_runs": [r["run"] for r in runs], "budgets": seed_spread(runs)}
    atomic_write_json(args.out / "seed_spread.json", spread)  # the demo reads it
    plot(runs, args.out / "curves.png")
    for run in runs:
        last = run["curve"][-1] if run["curve"] else {}
        print(run["run"], run["env_steps_last"], "held twice at:",
              (run["target_held_twice_at"] or {}).get("env_steps"), "last:",
              {k: last.get(k) for k in ("survival", "tracking_score", "joint_error_rad",
                                        "statue_joint_error_rad")})  # fmt: skip


if __name__ == "__main__":
    main()
