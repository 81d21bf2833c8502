"""Curves and numbers of the stand warm-start comparison (reads the run folders)."""

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

runs, out = Path(sys.argv[1]), Path(sys.argv[2])
summary = {}
fig, axes = plt.subplots(1, 3, figsize=(15, 4))
for name in ("baseline", "a2cf", "a2cf_warm"):
    metrics = json.loads((runs / name / "metrics.json").read_text())
    rows = metrics["iterations"]
    steps = [sum(r["env_steps"] for r in rows[: i + 1]) for i in range(len(rows))]
    evaluation = json.loads((runs / name / "eval.json").read_text())
    summary[name] = {
        "env_steps": steps[-1],
        "final_mean_episode_length": rows[-1]["mean_episode_length"],
        "final_skill_progress": rows[-1]["skill_progress"],
        "final_eta_norm": rows[-1]["eta_norm"],
        "eval_survival_assist_off": evaluation["survival_fraction"],
        "eval_mean_return_assist_off": evaluation["mean_return"],
    }
    warm = runs / name / "warmstart.json"
    if warm.is_file():
        summary[name]["warmstart_fit"] = json.loads(warm.read_text())["held_out_fit"]
    axes[0].plot(steps, [r["mean_episode_length"] or 0 for r in rows], label=name)
    axes[1].plot(steps, [r["applied_force_n"] for r in rows], label=name)
    axes[2].plot(steps, [(r["eta_norm"] or [0])[0] for r in rows], label=name)
titles = ("mean episode length [steps]", "applied force [N]", "|eta| [N, Nm]")
for ax, title in zip(axes, titles, strict=True):
    ax.set_xlabel("env steps")
    ax.set_title(title)
    ax.legend()
fig.tight_layout()
fig.savefig(out / "stand_warmstart.png", dpi=100)
(out / "stand_warmstart.json").write_text(json.dumps(summary, indent=2))
print(json.dumps(summary, indent=2))
