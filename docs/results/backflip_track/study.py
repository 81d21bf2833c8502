"""The backflip study's curves: per run folder, the policy alone from standing (its evals.jsonl)
against env steps: the pitch turned (mean and the best env), flips landed, the episode length and
the furthest phase reached; the help's size beside them where the run had help. Writes study.png
and study.json (each run's rows and its value at the env steps every run reached) into OUT.

    python docs/results/backflip_track/study.py OUT RUN_DIR...
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from optimal_control.files import atomic_savefig, atomic_write_json
from rl.studies.learning import read_evals

MARKS = (1.1e6, 3.1e6, 6.3e6, 9.2e6, 12.0e6, 15.0e6, 18.0e6, 24.0e6, 30.0e6)
"""Env steps at which every run that reached them is compared."""


def flip_rows(run_dir: Path) -> list[dict]:
    """One row per evaluation: env steps, turn mean / max [rad], flips landed, episode length
    [s], share of episodes whose furthest phase was air or land."""
    rows = []
    for r in read_evals(run_dir):
        m = r.get("task_metrics") or {}
        if "turn_rad_mean" not in m:
            continue
        phases = m.get("phase_reached", {})
        rows.append(
            {
                "iteration": r["iteration"],
                "env_steps": r["env_steps"],
                "turn_rad_mean": m["turn_rad_mean"],
                "turn_rad_max": m["turn_rad_max"],
                "flips_landed": m["flips_landed"],
                "episode_s": r["mean_episode_length_steps"] * 0.02,
                "reached_air_or_land": phases.get("air", 0.0) + phases.get("land", 0.0),
                "reached_land": phases.get("land", 0.0),
            }
        )
    return rows


def help_rows(run_dir: Path, window: int = 20) -> list[tuple[float, float, float]]:
    """The help on the training envs per iteration (TensorBoard's ``Assist/force_norm_n`` and
    ``Assist/torque_norm_nm``, the mean over all training envs, alone ones included), as
    (env steps, force [N], torque [N m]), each a mean over ``window`` iterations."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    cfg = json.loads((run_dir / "config.json").read_text())["train"]
    per_iteration = cfg["env"]["num_envs"] * cfg["num_steps_per_env"]
    series: dict[str, dict[int, float]] = {"Assist/force_norm_n": {}, "Assist/torque_norm_nm": {}}
    for events in sorted(run_dir.glob("events.out.tfevents*")):  # a resume adds a file
        acc = EventAccumulator(str(events), size_guidance={"scalars": 0})
        acc.Reload()
        for tag, values in series.items():
            if tag in acc.Tags()["scalars"]:
                values.update({e.step: e.value for e in acc.Scalars(tag)})
    force, torque = series.values()
    steps = sorted(set(force) & set(torque))
    rows = []
    for k in range(0, len(steps) - window + 1, window):
        chunk = steps[k : k + window]
        rows.append((
            (chunk[-1] + 1) * per_iteration,
            float(np.mean([force[i] for i in chunk])),
            float(np.mean([torque[i] for i in chunk])),
        ))  # fmt: skip
    return rows


def main(out: Path, run_dirs: list[Path]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {d.name: flip_rows(d) for d in run_dirs}
    summary = {}
    for name, rows in runs.items():
        if not rows:
            continue
        marks = {}
        for mark in MARKS:  # the 3 evaluations up to each mark the run reached
            upto = [r for r in rows if r["env_steps"] <= mark * 1.02]
            if rows[-1]["env_steps"] < mark * 0.98 or not upto:
                continue
            last3 = upto[-3:]
            marks[f"{mark / 1e6:g}M"] = {
                "turn_rad_mean": round(float(np.mean([r["turn_rad_mean"] for r in last3])), 2),
                "turn_rad_max_best": round(max(r["turn_rad_max"] for r in upto), 2),
                "reached_land": round(float(np.mean([r["reached_land"] for r in last3])), 2),
                "flips_landed": round(float(np.mean([r["flips_landed"] for r in last3])), 3),
                "episode_s": round(float(np.mean([r["episode_s"] for r in last3])), 2),
            }
        helps = help_rows(next(d for d in run_dirs if d.name == name))
        summary[name] = {
            "evaluated_env_steps": rows[-1]["env_steps"],
            "help_at_the_end (force N, torque N m; mean of the last 20 iterations)": (
                [round(helps[-1][1], 2), round(helps[-1][2], 2)] if helps else None
            ),
            "flips_landed_best": max(r["flips_landed"] for r in rows),
            "at_env_steps (mean of the 3 evaluations up to it)": marks,
        }
    keys = [("turn_rad_mean", "turn alone, mean [rad]"), ("turn_rad_max", "turn alone, best env [rad]"),
            ("flips_landed", "flips landed alone"), ("episode_s", "episode length alone [s]")]  # fmt: skip
    fig, axes = plt.subplots(1, len(keys) + 1, figsize=(4.6 * (len(keys) + 1), 3.8))
    for k_run, d in enumerate(run_dirs):
        name, rows, color = d.name, runs[d.name], f"C{k_run % 10}"  # one colour per run
        x = np.array([r["env_steps"] for r in rows]) / 1e6
        for ax, (k, _) in zip(axes, keys, strict=False):
            ax.plot(x, [r[k] for r in rows], marker=".", ms=3, lw=1, label=name, color=color)
        helps = help_rows(d)
        if helps:
            axes[-1].plot([h[0] / 1e6 for h in helps], [h[1] for h in helps], lw=1, color=color)
    axes[-1].set_xlabel("env steps [M]")
    axes[-1].set_ylabel("help in training: mean force [N]")
    axes[-1].grid(alpha=0.3)
    for ax, (k, label) in zip(axes, keys, strict=False):
        ax.set_xlabel("env steps [M]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if k.startswith("turn"):
            ax.axhline(2 * np.pi - 0.5, color="k", ls="--", lw=0.8)
    axes[0].legend(fontsize=7)
    fig.suptitle("backflip by tracking, the policy alone from standing (32 fresh envs)")
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    atomic_savefig(fig, out / "study.png", dpi=100)
    helps = {d.name: help_rows(d) for d in run_dirs}  # (env steps, force N, torque N m)
    atomic_write_json(out / "study.json", {"summary": summary, "runs": runs, "help": helps})
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), [Path(p) for p in sys.argv[2:]])
