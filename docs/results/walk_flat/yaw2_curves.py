"""Today's walk-flat recipe (yaw tracking 2.0): the policy alone's survival, velocity error and
yaw-rate error against env steps, A2CF beside the baseline per seed (and the no-pi ablation on the
Dec 5 recipe), from the records in this folder (32-env evaluations; ``yaw2_curves.png``).
Usage: python docs/results/walk_flat/yaw2_curves.py"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

HERE = Path(__file__).resolve().parent
RUNS = (
    ("A2CF warm, seed 0", "walkflat_a2cf_warm_yaw2_128_s0", "C0", "-"),
    ("baseline, seed 0", "walkflat_baseline_yaw2_128_s0", "C1", "-"),
    ("A2CF warm, seed 1", "walkflat_a2cf_warm_yaw2_128_s1", "C0", "--"),
    ("baseline, seed 1", "walkflat_baseline_yaw2_128_s1", "C1", "--"),
    ("no-pi warm, seed 0 (yaw 0.5)", "walkflat_no-pi_warm_128_s0", "C2", ":"),
)
PANELS = (
    ("survival_fraction", "survival alone", 0.9),
    ("lin_vel_error_mps", "velocity error [m/s]", 0.25),
    ("yaw_rate_error_rps", "yaw-rate error [rad/s]", None),
)


def main() -> None:
    fig, axes = plt.subplots(1, len(PANELS), figsize=(15, 4))
    for label, run, color, style in RUNS:
        rows = [json.loads(x) for x in (HERE / run / "evals.jsonl").read_text().splitlines() if x]
        steps = [r["env_steps"] / 1e6 for r in rows]
        for ax, (key, _, _) in zip(axes, PANELS, strict=True):
            values = [r[key] if key in r else r["task_metrics"][key] for r in rows]
            ax.plot(steps, values, style, color=color, label=label, lw=1.2)
    for ax, (_, name, target) in zip(axes, PANELS, strict=True):
        if target is not None:
            ax.axhline(target, color="k", lw=0.8, ls="--")
        ax.set_xlabel("env steps [M]")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[2].axhline(0.45, color="0.5", lw=0.8, ls=":", label="standing still (about)")
    axes[2].legend(fontsize=7)
    fig.suptitle("walk-flat, yaw tracking 2.0 (today's recipe): the policy alone, 32 fresh envs")
    fig.tight_layout()
    fig.savefig(HERE / "yaw2_curves.png", dpi=90)


if __name__ == "__main__":
    main()
