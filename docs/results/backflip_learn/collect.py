"""Collect the reduced backflip benchmark (``run.sh``): curves and a summary of baseline vs a2cf.

Reads ``runs/backflip_learn/<mode>/metrics.json`` (per-iteration rows) and the TensorBoard events
(the task's ``Skill/backflip_success_rate`` and ``Backflip/phase_*`` fractions, logged per
iteration), writes ``summary.json`` and ``curves.png`` next to this file.

    .venv/bin/python docs/results/backflip_learn/collect.py [RUNS_DIR]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402

HERE = Path(__file__).parent
MODES = ("baseline", "a2cf")
PHASES = ("stand", "crouch", "jump", "air", "land")
TAGS = ("Skill/backflip_success_rate", *(f"Backflip/phase_{p}" for p in PHASES))


def scalars(run: Path) -> dict[str, dict[int, float]]:
    """Per tag: iteration -> value, over every events file of the run (resumed chunks)."""
    out: dict[str, dict[int, float]] = {tag: {} for tag in TAGS}
    for events in sorted(run.glob("events.out.tfevents*")):
        acc = EventAccumulator(str(events), size_guidance={"scalars": 0})
        acc.Reload()
        for tag in TAGS:
            if tag in acc.Tags()["scalars"]:
                for ev in acc.Scalars(tag):
                    out[tag][ev.step] = ev.value
    return out


def main(runs: Path) -> None:
    """Write the summary and the figure."""
    summary, curves = {}, {}
    loaded = {m: json.loads((runs / m / "metrics.json").read_text()) for m in MODES}
    common = min(len(loaded[m]["iterations"]) for m in MODES)  # same budget for both modes
    for mode in MODES:
        run = runs / mode
        metrics = loaded[mode]
        rows = metrics["iterations"][:common]
        tb = scalars(run)
        it = np.array([r["iteration"] for r in rows])
        curves[mode] = {
            "iteration": it,
            "return": np.array([r["mean_episode_return"] for r in rows]),
            "length": np.array([r["mean_episode_length"] for r in rows]),
            "eta_norm": np.array([r["eta_norm"] or [np.nan] * len(PHASES) for r in rows]),
            **{tag: np.array([tb[tag].get(int(i), np.nan) for i in it]) for tag in TAGS},
        }
        last = slice(-20, None)
        c = curves[mode]
        summary[mode] = {
            "iterations_compared": common,
            "iterations_done": metrics["iterations_done"],
            "env_steps": int(sum(r["env_steps"] for r in rows)),
            "mean_iteration_time_s": metrics["mean_iteration_time_s"],
            "mean_episode_return_first_20": float(np.nanmean(c["return"][:20])),
            "mean_episode_return_last_20": float(np.nanmean(c["return"][last])),
            "mean_episode_length_steps_last_20": float(np.nanmean(c["length"][last])),
            "success_rate_last_20": float(np.nanmean(c["Skill/backflip_success_rate"][last])),
            "max_success_rate": float(np.nanmax(c["Skill/backflip_success_rate"])),
            "phase_fraction_last_20": {
                p: float(np.nanmean(c[f"Backflip/phase_{p}"][last])) for p in PHASES
            },
            "final_eta_norm_per_phase": (
                dict(zip(PHASES, rows[-1]["eta_norm"], strict=True))
                if rows[-1]["eta_norm"] is not None
                else None
            ),
            "final_curriculum": metrics["curriculum"],
        }
    (HERE / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")

    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for mode in MODES:
        c = curves[mode]
        axes[0, 0].plot(c["iteration"], c["Skill/backflip_success_rate"], label=mode)
        axes[0, 1].plot(c["iteration"], c["return"], label=mode)
        for p, ls in (("crouch", ":"), ("jump", "--"), ("air", "-")):
            axes[1, 0].plot(c["iteration"], c[f"Backflip/phase_{p}"], ls, label=f"{mode} {p}")
    for k, p in enumerate(PHASES):
        axes[1, 1].plot(curves["a2cf"]["iteration"], curves["a2cf"]["eta_norm"][:, k], label=p)
    axes[0, 0].set_title("success rate (window of 256 episodes)")
    axes[0, 1].set_title("mean episode return")
    axes[1, 0].set_title("fraction of env steps in phase")
    axes[1, 1].set_title("a2cf: |eta| per phase [N, Nm mixed]")
    for ax in axes.flat:
        ax.set_xlabel("iteration")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(HERE / "curves.png", dpi=100)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/backflip_learn"))
