"""The output folder of ``a2cf-mb demo``: its names, ``summary.json`` (built from the run
folders' files), the learning-curve figure and ``report.md`` (rendered from the summary alone).

:mod:`a2cf_mb.demo` runs the stages; this module reads what they wrote and says what it shows,
no more: which run's policy alone is ahead by the task's skill metric, by how much, at which
budget.
"""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path
from typing import Any

from a2cf_mb.progress import duration_str
from optimal_control.files import atomic_savefig
from rl.runs.folder import (
    CONFIG_FILE,
    CURRICULUM_LOG,
    EVAL_FILE,
    EVALS_LOG,
    METRICS_FILE,
    WARMSTART_FILE,
)

BASELINE = "baseline"
"""Run name of the baseline (motion policy only)."""
A2CF = "a2cf_warm"
"""Run name of A2CF with the warm-started force agent."""
LONGER_ITERATIONS = 1600
"""The longer budget the report suggests (1600 x 128 envs x 24 steps = 4.9 M env steps)."""

REPORT_FILE = "report.md"
SUMMARY_FILE = "summary.json"
CURVES_FILE = "demo_curves.png"
ORACLE_DIR = "oracle"
RUNS_DIR = "runs"
VIDEOS_DIR = "videos"
LOGS_DIR = "logs"
ZOO_DIR = "zoo"
DEMO_ENTRIES = frozenset(
    {REPORT_FILE, SUMMARY_FILE, CURVES_FILE, ORACLE_DIR, RUNS_DIR, VIDEOS_DIR, LOGS_DIR, ZOO_DIR}
)
"""What a demo writes into its output folder; ``--overwrite`` deletes only a folder holding
nothing else."""


def relative(path: str | Path | None, out: Path) -> str | None:
    """``path`` relative to the output folder ``out`` (as given when outside it; None if empty)."""
    if not path:
        return None
    try:
        return str(Path(path).resolve().relative_to(out.resolve()))
    except ValueError:
        return str(path)


# ------------------------------------------------------------------------------------- summary
def oracle_entry(out: Path, command: str, wall_s: float) -> dict[str, Any]:
    """The oracle's entry of summary.json from ``oracle.json`` (``command``: how it was run)."""
    from optimal_control.artifact import OracleArtifact

    art = OracleArtifact.read_summary(out / ORACLE_DIR)
    return {
        "folder": ORACLE_DIR,
        "command": command,
        "wall_time_s": wall_s,
        "phases": list(art.phase_names),
        "axes": art.raw.get("axes"),
        "eta0": art.eta0.tolist(),
        "eta0_frame": art.eta0_frame,
        "novice_model": art.raw.get("novice_model"),
        "rule": art.raw.get("rule"),
        "plots": sorted(
            f"{ORACLE_DIR}/plots/{p.name}" for p in (out / ORACLE_DIR / "plots").glob("*.png")
        ),
    }


def _json_file(path: Path) -> Any:
    return json.loads(path.read_text()) if path.is_file() else None


def read_run(
    out: Path,
    name: str,
    arguments: list[str],
    train_wall_s: float,
    eval_wall_s: float,
    metric: str,
) -> dict[str, Any]:
    """A run's entry of summary.json from its run folder (metrics, evaluation, warm start)."""
    run_dir = out / RUNS_DIR / name
    metrics = json.loads((run_dir / METRICS_FILE).read_text())
    evaluation = json.loads((run_dir / EVAL_FILE).read_text())
    config = json.loads((run_dir / CONFIG_FILE).read_text())["train"]
    warm = _json_file(run_dir / WARMSTART_FILE)
    return run_entry(
        name=name,
        command="a2cf-mb " + shlex.join(arguments),
        config=config,
        metrics=metrics,
        evaluation=evaluation,
        warmstart=warm,
        train_wall_s=train_wall_s,
        eval_wall_s=eval_wall_s,
        out=out,
        metric=metric,
    )


def run_entry(
    name: str,
    command: str,
    config: dict[str, Any],
    metrics: dict[str, Any],
    evaluation: dict[str, Any],
    warmstart: dict[str, Any] | None,
    train_wall_s: float,
    eval_wall_s: float,
    out: Path,
    metric: str,
) -> dict[str, Any]:
    """A run's entry of summary.json from its files' contents (``config``: the ``train`` part of
    config.json; ``evaluation``: eval.json; ``warmstart``: warmstart.json or None; ``metric``: the
    task's skill metric, copied to the top of ``alone``)."""
    task_metrics = dict(evaluation.get("task_metrics", {}))
    if "plot" in task_metrics:
        task_metrics["plot"] = relative(task_metrics["plot"], out)
    alone = {
        key: evaluation[key]
        for key in ("survival_fraction", "mean_return", "mean_episode_length_steps", "num_envs")
    }
    alone.update(
        {metric: task_metrics.get(metric)} if metric else {},
        target_reached=evaluation["target_reached"],
        task_metrics=task_metrics,
    )
    warm = None
    if warmstart is not None:
        distill = warmstart["config"]
        fit = warmstart.get("held_out_fit", {})
        warm = {
            "coach": warmstart.get("coach"),
            "env_steps": distill["rounds"] * distill["steps_per_round"] * config["env"]["num_envs"],
            "share_of_states_helped": warmstart.get("share_of_states_helped"),
            "held_out_r2": {axis: v["r2"] for axis, v in fit.items()},
        }
    during = metrics.get("alone_evaluations", [])
    return {
        "mode": config["mode"],
        "run_dir": f"{RUNS_DIR}/{name}",
        "command": command,
        "iterations": metrics["iterations_done"],
        "env_steps": sum(r["env_steps"] for r in metrics["iterations"]),
        "num_envs": config["env"]["num_envs"],
        "num_steps_per_env": config["num_steps_per_env"],
        "train_wall_time_s": train_wall_s,
        "eval_wall_time_s": eval_wall_s,
        "mean_iteration_time_s": metrics.get("mean_iteration_time_s"),
        "warmstart": warm,
        "alone": alone,
        "sim2sim": {
            key: evaluation["sim2sim"][key]
            for key in ("survival_fraction", "mean_return", "mean_episode_length_steps")
        },
        "alone_during_training": {
            "evaluations": len(during),
            "target_held_at": metrics.get("alone_target_held_at"),
            "log": f"{RUNS_DIR}/{name}/{EVALS_LOG}",
        },
        "video": relative(evaluation.get("video"), out),
        "video_note": evaluation.get("video_note"),
    }


SURVIVAL = "survival_fraction"
"""What runs are compared by where the task's target is survival alone (no skill metric)."""


def compare(runs: dict[str, dict[str, Any]], metric: str) -> dict[str, Any]:
    """Which run's policy alone is ahead by ``metric`` (lower is better, as the task's target
    bounds it above), or by survival (higher is better) where the task has no metric (``""``);
    ``ahead`` None when they are level or the metric is missing."""
    key = metric or SURVIVAL
    higher = not metric
    values = {name: run["alone"].get(key) for name, run in runs.items()}
    result: dict[str, Any] = {
        "metric": key,
        "higher_is_better": higher,
        "values": values,
        "env_steps": {name: run["env_steps"] for name, run in runs.items()},
        "ahead": None,
        "by": 0.0,
    }
    if any(not isinstance(v, (int, float)) for v in values.values()):
        return result
    (first, a), (second, b) = sorted(values.items(), key=lambda kv: -kv[1] if higher else kv[1])
    if a != b:
        result.update(ahead=first, by=abs(b - a))
    return result


def build_summary(
    task: str,
    config: dict[str, Any],
    oracle: dict[str, Any],
    runs: dict[str, dict[str, Any]],
    target: dict[str, Any],
    wall_time_s: float,
    seed_spread: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """summary.json: the task, the demo's config (with ``eval_interval`` and
    ``a2cf_variant_flags``), the oracle, each run, the comparison and the wall time. ``target``:
    the task's skill target (``describe``, ``metric``, ``max_metric``, ``fall_error``,
    ``one_episode_of_the_mean``, ``episode_length_s``). ``seed_spread``: the baseline's metric
    over seeds at the demo's budget, measured in a study (``metric``, ``values``, ``env_steps``,
    ``source``), or None where none was measured."""
    return {
        "task": task,
        "config": config,
        "target": target,
        "oracle": oracle,
        "runs": runs,
        "comparison": compare(runs, target["metric"]),
        "seed_spread": seed_spread,
        "wall_time_s": wall_time_s,
    }


def spread_of(summary: dict[str, Any]) -> float | None:
    """Width (max - min) of the measured seed spread of the comparison's metric, or None."""
    spread = summary.get("seed_spread")
    if not spread or spread.get("metric") != summary["comparison"]["metric"]:
        return None
    values = list(spread["values"].values())
    return max(values) - min(values) if len(values) > 1 else None


# ------------------------------------------------------------------------------------- figures
def plot_curves(out: Path, summary: dict[str, Any]) -> str:
    """``demo_curves.png``: the policy alone during training (skill metric, survival) and the
    A2CF run's bound and applied force, over env steps; returns its name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rl.evaluation.alone import curve_arrays

    metric = summary["target"]["metric"] or "mean_episode_length_steps"
    fig, axes = plt.subplots(2, 2, figsize=(12, 7))
    for i, (name, run) in enumerate(summary["runs"].items()):
        color = f"C{i}"
        text = (out / run["run_dir"] / EVALS_LOG).read_text()
        rows = [json.loads(line) for line in text.splitlines()]
        axes[0, 0].plot(*curve_arrays(rows, metric), marker="o", color=color, label=name)
        axes[0, 1].plot(
            *curve_arrays(rows, "survival_fraction"), marker="o", color=color, label=name
        )
        curriculum = out / run["run_dir"] / CURRICULUM_LOG
        if not curriculum.is_file():
            continue  # the baseline has no assist agent
        rows = [json.loads(line) for line in curriculum.read_text().splitlines()]
        per_iteration = run["num_envs"] * run["num_steps_per_env"]
        steps = [(r["iteration"] + 1) * per_iteration for r in rows]
        force = [max(math.hypot(*p[:3]) for p in r["eta"]) for r in rows]
        torque = [max(math.hypot(*p[3:]) for p in r["eta"]) for r in rows]
        axes[1, 0].plot(steps, force, color=color, label=f"{name}: force [N]")
        axes[1, 0].plot(steps, torque, color=color, ls="--", label=f"{name}: torque [N m]")
        axes[1, 1].plot(steps, [r["applied_force_n"] for r in rows], color=color, label=name)
    if summary["target"]["metric"]:
        axes[0, 0].axhline(summary["target"]["max_metric"], color="k", ls=":", lw=1, label="target")
    axes[0, 0].set_ylim(bottom=0.0)
    axes[0, 1].axhline(summary["target"]["min_survival"], color="k", ls=":", lw=1, label="target")
    axes[0, 1].set_ylim(-0.03, 1.03)
    for ax in (axes[1, 0], axes[1, 1]):
        ax.set_ylim(bottom=0.0)
    titles = (
        (
            f"policy alone: {metric} (lower is better)"
            if summary["target"]["metric"]
            else "policy alone: episode length [steps]",
            "policy alone: survival [-]",
        ),
        ("A2CF assist bound |eta| (largest phase)", "applied assist force [N]"),
    )
    for row, pair in zip(axes, titles, strict=True):
        for ax, title in zip(row, pair, strict=True):
            ax.set_title(title)
            ax.set_xlabel("env steps")
            ax.grid(alpha=0.3)
            if ax.has_data():
                ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_savefig(fig, out / CURVES_FILE, dpi=100)
    plt.close(fig)
    return CURVES_FILE


# -------------------------------------------------------------------------------------- report
def verdict(summary: dict[str, Any]) -> str:
    """The comparison in one or two sentences (what the numbers show, no more)."""
    cmp = summary["comparison"]
    metric = cmp["metric"]
    runs = summary["runs"]
    steps = {cmp["env_steps"][n] for n in runs}
    budget = (
        f"{steps.pop():,} env steps each"
        if len(steps) == 1
        else ", ".join(f"{n} {s:,}" for n, s in cmp["env_steps"].items()) + " env steps"
    )
    values = cmp["values"]
    if any(not isinstance(v, (int, float)) for v in values.values()):
        return f"No comparison: the evaluations have no {metric}."
    shown = " vs ".join(f"{n} {v:.3f}" for n, v in values.items())
    target = (
        f"target >= {summary['target']['min_survival']:g}"
        if cmp.get("higher_is_better")
        else f"target <= {summary['target']['max_metric']:g}"
    )
    direction = "higher" if cmp.get("higher_is_better") else "lower"
    if cmp["ahead"] is None:
        fell = all(r["alone"]["survival_fraction"] == 0.0 for r in runs.values())
        return (
            f"Neither run is ahead by the policy-alone {metric} at {budget}: {shown} ({target})"
            + ("; both policies fell in every evaluation episode." if fell else ".")
        )
    behind = next(n for n in runs if n != cmp["ahead"])
    text = (
        f"{cmp['ahead']} is ahead of {behind} by the policy-alone {metric} at {budget}: "
        f"{shown}, {cmp['by']:.3f} {direction} ({target})."
    )
    width = spread_of(summary)
    if width is not None:
        source = summary["seed_spread"]["source"]
        text += (
            f" The baseline's {metric} alone spans {width:.3f} over seeds at about this budget "
            f"({source}): "
            + (
                "the difference is inside that spread, so it is noise between seeds, not a "
                "difference between the methods."
                if cmp["by"] <= width
                else "the difference is larger than that spread (one seed still decides little)."
            )
        )
    return text


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *("| " + " | ".join(r) + " |" for r in rows),
    ]


def _zoo_section(zoo: dict[str, Any]) -> list[str]:
    """report.md's first section: each zoo skill's video, contact sheet and confirmed figures."""
    if not zoo:
        return []
    lines = [
        "## 0. What the toolkit has learned (the zoo)",
        "Each skill's best confirmed policy, played from its bundle alone by the standalone "
        "runner (`a2cf-mb play SKILL`): nominal model, no pushes.",
        "",
    ]
    for skill, entry in zoo.items():
        judge = entry.get("judge") or {}
        lines += [
            f"- **{skill}**: [video]({entry['video']}); judge: {judge.get('judge', '-')}; "
            f"confirmed: {judge.get('confirmed', '-')}",
            "",
            f"  ![{skill}]({entry['contact_sheet']})",
            "",
        ]
    return lines


def render_report(summary: dict[str, Any], out: Path) -> str:
    """report.md from summary.json's content (figures linked relative to ``out``)."""
    cfg, oracle, runs, target = (summary[k] for k in ("config", "oracle", "runs", "target"))
    metric = target["metric"]
    base, a2cf = runs[BASELINE], runs[A2CF]
    warm = a2cf["warmstart"] or {}
    per_run = base["num_envs"] * base["num_steps_per_env"]
    if oracle:
        phases, eta0 = oracle["phases"], oracle["eta0"]
    else:
        eta0 = cfg.get("eta0") or []
        phases = [summary["task"]] if len(eta0) == 1 else [f"phase {i}" for i in range(len(eta0))]
    eta_rows = [
        [phase, *(f"{v:.1f}" for v in row)] for phase, row in zip(phases, eta0, strict=True)
    ]
    coach = "the oracle" if oracle else f"the {cfg.get('warmstart')} coach"
    warm_flag = f"OUT/{ORACLE_DIR}" if oracle else cfg.get("warmstart")
    metric_column = metric or "episode length [steps]"

    def reached_at(run: dict[str, Any]) -> str:
        at = run["alone_during_training"]["target_held_at"]
        return f"{at['env_steps']:,} env steps" if at else "not reached"

    train_rows = [
        [
            f"`{name}`", run["mode"], f"{run['iterations']} x {run['num_envs']} x "
            f"{run['num_steps_per_env']} = {run['env_steps']:,}",
            duration_str(run["train_wall_time_s"]), reached_at(run),
        ]
        for name, run in runs.items()
    ]  # fmt: skip

    def value(run: dict[str, Any], key: str) -> str:
        if not key:  # no skill metric: the episode length alone
            return f"{run['alone']['mean_episode_length_steps']:.0f}"
        v = run["alone"]["task_metrics"].get(key)
        return f"{v:.3f}" if isinstance(v, (int, float)) else "-"

    def joint_cell(run: dict[str, Any]) -> str:
        """The mean joint error, beside the statue's on the same frames where it was scored."""
        if "joint_error_rad" not in run["alone"]["task_metrics"]:
            return value(run, "joint_all_rad")
        return f"{value(run, 'joint_error_rad')} (statue {value(run, 'statue_joint_error_rad')})"

    eval_rows = [
        [
            f"`{name}`", f"{run['alone']['survival_fraction']:.0%}", value(run, metric),
            joint_cell(run), "yes" if run["alone"]["target_reached"] else "no",
            f"{run['sim2sim']['survival_fraction']:.0%}",
            f"{run['sim2sim']['mean_episode_length_steps']:.0f}",
            f"[video]({run['video']})" if run["video"] else (run["video_note"] or "-"),
        ]
        for name, run in runs.items()
    ]  # fmt: skip
    plots = [
        f"![{name}: errors over the episode]({p})"
        for name, p in ((n, r["alone"]["task_metrics"].get("plot")) for n, r in runs.items())
        if p and (out / p).is_file()
    ]
    # collect + learn of the slower run (rsl-rl's iteration time; the runs shared the cores)
    seconds_per_iteration = max(r["mean_iteration_time_s"] or 0.0 for r in runs.values())
    flags = " ".join(cfg["a2cf_variant_flags"])
    flags = (
        f"plus the variant flags `{flags}`"
        if flags
        else 'with the default curriculum (docs/training.md, "The curriculum")'
    )
    return "\n".join(
        [
            f"# a2cf-mb demo: {summary['task']}, baseline vs A2CF warm-started from {coach}",
            "",
            f"One task end to end, {duration_str(summary['wall_time_s'])} on this machine. "
            f"Both runs: seed {cfg['seed']}, {base['num_envs']} envs x "
            f"{base['num_steps_per_env']} steps x {cfg['iterations']} iterations = "
            f"{base['env_steps']:,} env steps, one core each, side by side"
            + (f", update `{' '.join(cfg['recipe_flags'])}`" if cfg.get("recipe_flags") else "")
            + ". Numbers: "
            f"[summary.json]({SUMMARY_FILE}); logs: `{LOGS_DIR}/`.",
            "",
            *_zoo_section(summary.get("zoo") or {}),
            *(
                [
                    "## 1. The oracle",
                    f"`{oracle['command']}` ({duration_str(oracle['wall_time_s'])}): the built-in "
                    "choreography, the per-frame wrench QP along it, and the initial assist bound "
                    "eta0 the A2CF run starts from (the baseline has no assist agent). Novice "
                    f"model: {oracle['novice_model']}. Frame of eta0: {oracle['eta0_frame']}.",
                ]
                if oracle
                else [
                    "## 1. The help",
                    f"The A2CF run's force agent starts from {cfg.get('help')}; the curriculum "
                    "shrinks the bound to zero (the figure in section 2), so the final policy "
                    "stands alone. The baseline has no assist agent.",
                ]
            ),
            "",
            *_table(
                ["phase", "fx [N]", "fy [N]", "fz [N]", "mx [N m]", "my [N m]", "mz [N m]"],
                eta_rows,
            ),
            "",
            *[f"![{Path(p).name}]({p})" for p in (oracle or {}).get("plots", [])],
            "",
            "## 2. Training: the same seed, envs and budget",
            *_table(
                [
                    "run",
                    "mode",
                    "iterations x envs x steps = env steps",
                    "wall time (start-up, warm start, PPO, evaluations)",
                    f"policy alone at target ({target['describe']}) at two consecutive "
                    "evaluations during training, from",
                ],
                train_rows,
            ),
            "",
            f"`{A2CF}`: `--mode a2cf --warmstart {warm_flag}` {flags}. Before PPO its "
            f"warm start distilled {coach}'s help into the force "
            f"agent in {warm.get('env_steps', 0):,} env steps, not counted in the budget above; "
            "held-out R^2 of the distilled head per axis: "
            + ", ".join(f"{k} {v:.2f}" for k, v in warm.get("held_out_r2", {}).items())
            + ".",
            "",
            "Commands (as run, with `--out`"
            + (" and the oracle folder" if oracle else "")
            + " absolute):",
            "",
            *[f"- `{run['command']}`" for run in runs.values()],
            "",
            "Each run evaluated its policy alone (assistance off, fresh envs, one episode each) "
            f"every {cfg['eval_interval']} iteration(s) and at its end (`evals.jsonl` in its run "
            "folder):",
            "",
            f"![curves]({summary['figure']})",
            "",
            "## 3. The motion policies alone (assistance off) at the end",
            f"{base['alone']['num_envs']} envs, one episode each (up to "
            f"{target['episode_length_s']:g} s), in the training physics and in the second "
            "simulator (`a2cf-mb eval --sim2sim`: 1 kHz explicit PD, URDF collision meshes).",
            *(
                [
                    f"`{metric}` = max(joint / 0.16 rad, (joint / statue) / 0.5), <= 1 tracks: "
                    "the mean joint error from the dance's first frame over the frames the robot "
                    "was up, against the paper's 0.16 rad and against half of what a *statue* "
                    "(the robot holding its standing pose) scores on the same frames, shown "
                    "beside it. The video is env 0's episode beside the reference (the ghost)."
                ]
                if metric == "tracking_score"
                else [
                    f"The target is the policy alone's survival ({target['describe']}): the robot "
                    f"up for the whole episode ({target['episode_length_s']:g} s) under the "
                    "task's pushes. The video is env 0's episode."
                ]
                if not metric
                else [
                    f"`{metric}` is the task's skill measure: the mean joint error at the episode's "
                    f"end, a fall counted as {target['fall_error']:g} rad; `joint_all_rad`: the mean "
                    "joint error over the steps the robot was up. The video is env 0's episode "
                    "(until it ends or falls)."
                ]
            ),
            "",
            *_table(
                [
                    "run",
                    "survival",
                    metric_column,
                    "joint error [rad]",
                    "target",
                    "survival (sim2sim)",
                    "episode length (sim2sim) [steps]",
                    "video",
                ],
                eval_rows,
            ),
            "",
            *plots,
            "",
            "## 4. What this shows",
            verdict(summary),
            "",
            f"- One seed and one budget: this is one comparison, not a measure of the spread "
            f"between seeds. One episode of {base['alone']['num_envs']} moves the mean "
            f"`{metric or SURVIVAL}` by up to {target['one_episode_of_the_mean']:.3f}."
            if spread_of(summary) is None
            else f"- One seed and one budget: this is one comparison. The spread between seeds "
            f"it must be read against: the baseline's `{metric}` "
            + ", ".join(f"{k} {v:.3f}" for k, v in summary["seed_spread"]["values"].items())
            + f" at {summary['seed_spread']['env_steps']:,} env steps "
            f"({summary['seed_spread']['source']}).",
            "- Survival alone at the end: "
            + "; ".join(
                f"{n} {r['alone']['survival_fraction']:.0%} (sim2sim "
                f"{r['sim2sim']['survival_fraction']:.0%})"
                for n, r in runs.items()
            )
            + ".",
            f"- The target ({target['describe']}) is reached alone at the end by: "
            + (
                ", ".join(n for n, r in runs.items() if r["alone"]["target_reached"])
                or "neither run"
            )
            + ".",
            f"- A longer budget: `a2cf-mb demo --iterations {LONGER_ITERATIONS} --out demo_long` "
            f"({LONGER_ITERATIONS * per_run:,} env steps per run; at the "
            f"{seconds_per_iteration:.2f} s per iteration measured here, about "
            f"{duration_str(LONGER_ITERATIONS * seconds_per_iteration)} of training, plus start-up "
            f"and evaluations). {cfg.get('study') or 'docs/results/track_learn'} measures the "
            "baseline's policy alone on this target over 3 seeds, each confirmed on 128 fresh "
            "envs.",
            "",
        ]
    )
