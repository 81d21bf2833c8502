"""Numbers of a warm-start comparison (reads the run folders of a run.sh in docs/results).

Usage: python docs/results/summarise_warmstart.py RUNS_DIR OUT_DIR NAME... [--length L...]

Per run: env steps, the first env step at which the training mean episode length reaches each
``--length`` threshold (with the run's own assistance), skill progress at the end, bound norm and
applied force at the start and end, the held-out fits of the warm start, and every assist-off
evaluation kept as ``eval_it<N>.json``. Writes ``summary.json`` and ``summary.md`` into OUT_DIR and
a figure ``curves.png`` (episode length, skill progress, applied force, bound norm against env
steps).
"""

import argparse
import json
from pathlib import Path

import matplotlib

from optimal_control.files import atomic_savefig, atomic_write_json, atomic_write_text

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

parser = argparse.ArgumentParser()
parser.add_argument("runs", type=Path)
parser.add_argument("out", type=Path)
parser.add_argument("names", nargs="+")
parser.add_argument("--length", type=float, nargs="*", default=[100.0, 150.0, 250.0])
args = parser.parse_args()

summary: dict = {}
fig, axes = plt.subplots(1, 4, figsize=(18, 4))
for name in args.names:
    run = args.runs / name
    rows = json.loads((run / "metrics.json").read_text())["iterations"]
    steps, total = [], 0
    for r in rows:
        total += r["env_steps"]
        steps.append(total)
    lengths = [r["mean_episode_length"] or 0.0 for r in rows]
    first = {}
    for level in args.length:
        hit = next((s for s, v in zip(steps, lengths, strict=True) if v >= level), None)
        first[f"{level:g}"] = hit
    tail = rows[-20:]
    entry = {
        "iterations": len(rows),
        "env_steps": steps[-1],
        "env_steps_to_episode_length": first,
        "final_mean_episode_length_last20": sum(lengths[-20:]) / len(lengths[-20:]),
        "final_skill_progress": rows[-1]["skill_progress"],
        "applied_force_n_first_last": [rows[0]["applied_force_n"], rows[-1]["applied_force_n"]],
        "eta_norm_first_last": [rows[0]["eta_norm"], rows[-1]["eta_norm"]],
        "mean_step_reward_last20": sum(r["mean_step_reward"] for r in tail) / len(tail),
        "evals_assist_off": {},
    }
    for path in sorted(run.glob("eval_it*.json")):
        ev = json.loads(path.read_text())
        keep = ("survival_fraction", "mean_episode_length_steps", "mean_return", "joint_all_rad",
                "joint_legs_rad", "joint_arms_rad", "base_position_m", "skill_learned")  # fmt: skip
        entry["evals_assist_off"][path.stem[len("eval_it") :]] = {
            k: ev.get(k, ev.get("task_metrics", {}).get(k)) for k in keep
        }
    warm = run / "warmstart.json"
    if warm.is_file():
        w = json.loads(warm.read_text())
        if "held_out_fit" in w and "coach" in w:
            entry["assist_fit_r2"] = {a: v["r2"] for a, v in w["held_out_fit"].items()}
            entry["share_of_states_helped"] = w["share_of_states_helped"]
        if "motion" in w:
            entry["motion_fit"] = {"r2": w["motion"]["r2"], "rmse_rad": w["motion"]["rmse_rad"]}
    summary[name] = entry
    axes[0].plot(steps, lengths, label=name)
    axes[1].plot(steps, [r["skill_progress"] for r in rows], label=name)
    axes[2].plot(steps, [r["applied_force_n"] for r in rows], label=name)
    axes[3].plot(steps, [(r["eta_norm"] or [0.0])[0] for r in rows], label=name)
titles = ("mean episode length [steps] (training, with help)", "skill progress [-]",
          "applied force |f| [N]", "bound norm |eta| [N, Nm]")  # fmt: skip
for ax, title in zip(axes, titles, strict=True):
    ax.set_xlabel("env steps")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
fig.tight_layout()
args.out.mkdir(parents=True, exist_ok=True)
atomic_savefig(fig, args.out / "curves.png", dpi=100)
atomic_write_json(args.out / "summary.json", summary)
lines = ["| run | env steps | steps to ep. length " + " / ".join(map(str, args.length))
         + " | ep. length (last 20 it) | eval (assist off): survival, ep. length, joint err [rad] |",
         "|---|---|---|---|---|"]  # fmt: skip
for name, e in summary.items():
    evals = "; ".join(
        f"it {it}: {v['survival_fraction']:.2f}, {v['mean_episode_length_steps']:.0f}, "
        f"{v['joint_all_rad'] if v['joint_all_rad'] is None else round(v['joint_all_rad'], 3)}"
        for it, v in sorted(e["evals_assist_off"].items(), key=lambda kv: int(kv[0]))
    )
    hits = " / ".join(
        "-" if v is None else f"{v / 1e3:.0f}k" for v in e["env_steps_to_episode_length"].values()
    )
    lines.append(f"| {name} | {e['env_steps'] / 1e6:.2f} M | {hits} | "
                 f"{e['final_mean_episode_length_last20']:.0f} | {evals} |")  # fmt: skip
atomic_write_text(args.out / "summary.md", "\n".join(lines) + "\n")
print("\n".join(lines))
