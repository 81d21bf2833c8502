"""Summarise the walk_kinds runs: per evaluation of the policy alone (32 fresh envs during
training), survival, ``command_score`` and each command kind's error over its bar; where the
target first held at two consecutive evaluations; a figure of the curves.

Usage: python docs/results/walk_kinds/summarise.py RUN_DIR... [--out DIR]
Writes DIR/summary.json and DIR/curves.png (DIR: this folder by default).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from optimal_control.files import atomic_savefig, atomic_write_json
from rl.runs.folder import read_run_jsonl
from rl.tasks.walk.evaluation import JUDGED_KINDS

ERROR_OF_KIND = {"forward": "lin_vel_error_mps", "backward": "lin_vel_error_mps",
                 "sideways": "lin_vel_error_mps", "turn": "yaw_rate_error_rps",
                 "mixed": "lin_vel_error_mps", "stop": "lin_vel_error_mps"}  # fmt: skip


def kind_ratios(metrics: dict) -> dict[str, float]:
    """Each judged kind's error over half of a robot standing still's (stop: its raw error)."""
    out = {}
    for row in metrics.get("per_command", []):
        key = ERROR_OF_KIND.get(row["command"])
        if key is None:
            continue
        bar = 0.5 * row[f"standing_still_{key}"]
        out[row["command"]] = row[key] / bar if bar > 1e-6 else row[key]
    return out


def summarise(run_dir: Path) -> dict:
    """The run's evaluations (env steps, survival, command score, per-kind ratios) and the first
    pair of consecutive evaluations that met the target."""
    rows = read_run_jsonl(run_dir / "evals.jsonl", "evaluations", "rerun the evaluation")
    evals = [
        {
            "iteration": r["iteration"],
            "env_steps": r["env_steps"],
            "survival": r["survival_fraction"],
            "command_score": r.get("task_metrics", {}).get("command_score"),
            "kinds": kind_ratios(r.get("task_metrics", {})),
            "target_reached": r["target_reached"],
        }
        for r in rows
    ]
    pair = next(
        (
            a
            for a, b in zip(evals, evals[1:], strict=False)
            if a["target_reached"] and b["target_reached"]
        ),
        None,
    )
    return {"run": run_dir.name, "evals": evals, "held_twice_at": pair}


def plot(summaries: list[dict], path: Path) -> None:
    """Survival, command score and per-kind ratios against env steps, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = ["survival", "command_score", *JUDGED_KINDS]
    fig, axes = plt.subplots(2, 4, figsize=(16, 7))
    for ax, name in zip(axes.flat, panels, strict=False):
        for s in summaries:
            x = [e["env_steps"] / 1e6 for e in s["evals"]]
            if name in ("survival", "command_score"):
                y = [e[name] if e[name] is not None else float("nan") for e in s["evals"]]
            else:
                y = [e["kinds"].get(name, float("nan")) for e in s["evals"]]
            ax.plot(x, y, label=s["run"], lw=1)
        bar = {"survival": 0.9, "stop": 0.15}.get(name, 1.0)
        ax.axhline(bar, color="k", ls="--", lw=0.8)
        ax.set_title(name if name in ("survival", "command_score") else f"{name}: error / bar")
        ax.set_xlabel("env steps [M]")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("walk-flat, policy alone (32 fresh envs): every command kind judged")
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=90)
    plt.close(fig)


def main() -> None:
    """Command line (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent)
    args = parser.parse_args()
    summaries = [summarise(r) for r in args.runs]
    atomic_write_json(args.out / "summary.json", summaries, indent=1)
    plot(summaries, args.out / "curves.png")
    for s in summaries:
        last = s["evals"][-1] if s["evals"] else None
        if last:
            kinds = " ".join(f"{k} {v:.2f}" for k, v in last["kinds"].items())
            print(f"{s['run']}: {last['env_steps'] / 1e6:.2f} M, survival {last['survival']:.0%}, "
                  f"score {last['command_score']:.2f} ({kinds}); held twice at "
                  f"{s['held_twice_at'] and s['held_twice_at']['env_steps']}")  # fmt: skip


if __name__ == "__main__":
    main()
