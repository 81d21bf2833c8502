"""Learning studies judged by the motion policy alone: env steps (and wall time) to the task's
assistance-free target per run, mean and spread over seeds, and the curves behind them.

Reads run folders only: the evaluations during training (``evals.jsonl``) or, for runs trained
without them, ``a2cf-mb eval-curve``'s ``evals_checkpoints.jsonl``; the wall time per iteration
from ``metrics.json`` (or, for a live run, the checkpoint's logger rows are not read: wall time is
then the evaluation rows' order only). Used by ``a2cf-mb bench learn`` and ``docs/results``.
"""

from __future__ import annotations

import gzip
import json
from collections import defaultdict
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from optimal_control.files import atomic_savefig, atomic_write_json
from rl.evaluation.alone import curve_arrays, first_reached_once, target_held
from rl.runs.folder import (
    CHECKPOINT_EVALS_LOG,
    EVALS_LOG,
    METRICS_FILE,
    METRICS_LOG,
    load_run_config,
)
from rl.tasks.registry import resolve_task
from rl.training.config import PPOConfig

CONFIRM_MIN_ENVS = 128
"""Fresh envs an evaluation needs to confirm a target held during training [-]."""


def read_evals(run_dir: Path) -> list[dict[str, Any]]:
    """The run's alone-evaluation rows, oldest first (during-training rows preferred)."""
    for name in (EVALS_LOG, CHECKPOINT_EVALS_LOG):
        path = run_dir / name
        if path.is_file() and path.stat().st_size:
            rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
            return sorted(rows, key=lambda r: r["iteration"])
    return []


def read_metric_rows(run_dir: Path) -> list[dict[str, Any]]:
    """The run's per-iteration rows of ``metrics.json`` (or of a committed ``metrics.json.gz``);
    for a run still training (or its study record), the rows the runner appends to
    ``metrics.jsonl`` (or a committed ``metrics.jsonl.gz``)."""
    path = run_dir / METRICS_FILE
    if path.is_file():
        return json.loads(path.read_text()).get("iterations", [])
    packed = path.with_name(path.name + ".gz")
    if packed.is_file():
        return json.loads(gzip.decompress(packed.read_bytes())).get("iterations", [])
    live = run_dir / METRICS_LOG
    packed_live = live.with_name(live.name + ".gz")
    if live.is_file():
        text = live.read_text()
    elif packed_live.is_file():
        text = gzip.decompress(packed_live.read_bytes()).decode()
    else:
        return []
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def _wall_s_at(run_dir: Path, iteration: int) -> float | None:
    """Training wall time [s] of the first ``iteration`` iterations (metrics.json rows)."""
    rows = read_metric_rows(run_dir)
    if not rows or len(rows) < iteration:
        return None
    return float(sum(r["iteration_time_s"] for r in rows[:iteration]))


def confirmed_pair(run_dir: Path, rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The first evaluation row of two consecutive ones that reached the target where both
    checkpoints were confirmed on >= 128 fresh envs and every confirmation reached it too (a
    pair with a failed confirmation is passed over; the scan stops at the first pair held twice
    that has not been confirmed yet, since what it would give is unknown)."""
    for first, second in pairwise(rows):
        if not (first["target_reached"] and second["target_reached"]):
            continue
        checks = [confirmations_at(run_dir, r["iteration"]) for r in (first, second)]
        if not all(c["target_reached"] for check in checks for c in check):
            continue  # a checkpoint of this pair failed on the larger envs
        if not all(checks):
            return None
        return first
    return None


def confirmations_at(
    run_dir: Path, iteration: int, min_envs: int = CONFIRM_MIN_ENVS
) -> list[dict[str, Any]]:
    """Evaluations of the checkpoint at ``iteration`` on at least ``min_envs`` fresh envs
    (``a2cf-mb eval-curve --num-envs 128`` writes them to ``evals_checkpoints.jsonl``)."""
    path = run_dir / CHECKPOINT_EVALS_LOG
    if not path.is_file():
        return []
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [r for r in rows if r["iteration"] == iteration and r["num_envs"] >= min_envs]


def run_summary(run_dir: str | Path) -> dict[str, Any]:
    """One run: task, mode, seed, its evaluations and where its target first held at two
    consecutive evaluations (``reached_at_*``), with that checkpoint's confirmations on
    >= 128 fresh envs (``confirmed``: there are some and each reached the target), and the first
    such pair whose two checkpoints are both confirmed (``confirmed_pair_at_*``)."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    task = resolve_task(cfg)
    rows = read_evals(run_dir)
    branch = branch_of(run_dir)
    # a branch's own evaluations start after its branch point: before it the run is its parent
    own = [r for r in rows if r["iteration"] > branch["iteration"]] if branch else rows
    first = target_held(own)
    once = first_reached_once(own)
    confirmations = confirmations_at(run_dir, first["iteration"]) if first else []
    pair = confirmed_pair(run_dir, own)
    metric = task.target.metric
    last = rows[-1] if rows else None
    return {
        "run": run_dir.name,
        "task": cfg.task,
        "mode": cfg.mode,
        "variant": run_variant(cfg, branch),
        "branched_from": branch,
        "seed": cfg.seed,
        "num_envs": cfg.env.num_envs,
        "target": task.target.describe(),
        "metric": metric,
        "max_metric": task.target.max_metric if metric else None,
        "evaluations": len(rows),
        "evaluated_env_steps": last["env_steps"] if last else 0,
        "reached_at_env_steps": first["env_steps"] if first else None,
        "reached_at_iteration": first["iteration"] if first else None,
        "reached_at_wall_s": _wall_s_at(run_dir, first["iteration"]) if first else None,
        "first_reached_once_at_env_steps": once["env_steps"] if once else None,
        # the stricter reading: both checkpoints of the pair confirmed on >= 128 envs
        "confirmed_pair_at_env_steps": pair["env_steps"] if pair else None,
        "confirmed_pair_at_iteration": pair["iteration"] if pair else None,
        "confirmations": confirmations,
        "confirmed": bool(confirmations) and all(c["target_reached"] for c in confirmations),
        "last_survival": last["survival_fraction"] if last else None,
        "last_metric": last.get("task_metrics", {}).get(metric) if last and metric else None,
        "best_survival": max((r["survival_fraction"] for r in rows), default=None),
    }


BRANCH_FILE = "branch.json"
"""Written into a run folder branched from another run's checkpoint (the study's ``branch.py``):
``{"run": parent run name, "iteration": K, "overrides": {field: value}}``."""


def branch_of(run_dir: str | Path) -> dict[str, Any] | None:
    """The run's :data:`BRANCH_FILE` (where it was branched from), or None for a run trained from
    scratch."""
    path = Path(run_dir) / BRANCH_FILE
    if not path.is_file():
        return None
    try:
        branch = json.loads(path.read_text())
        int(branch["iteration"]), dict(branch["overrides"])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise ValueError(
            f"{path} is damaged ({err}); it should hold the parent run, the iteration and the "
            "overrides the branch was made with: restore it from the records, or delete it"
        ) from err
    return branch


def run_variant(cfg: Any, branched_from: dict[str, Any] | None = None) -> str:
    """The name a study groups a run under: its mode, ``+warm`` when its force agent was
    warm-started, ``+paper`` when its curriculum follows the paper's rules, else the curriculum's
    skill trigger (``skill:<measure>@<progress>``), its fixed schedule (``anneal:<iterations>``,
    ``anneal:off``), whose KL sets the learning rate (``kl:all``) and whether the assist actions
    leave PPO's ratio after the help (``ratio:while_helping``) where they differ from today's defaults;
    for any mode, its update (``update:<PPO passes>+<encoder passes>``) where it differs from its
    task's today; last, its task changes (``task:<field>=<value>,...``; ``@K`` after a change made
    where the run was branched from another at iteration K)."""
    name = cfg.mode
    if cfg.warmstart:
        name += "+warm"
    if cfg.mode != "baseline":
        name += _curriculum_variant(cfg.curriculum)
        if cfg.ppo.kl_actions != PPOConfig().kl_actions:
            name += f" kl:{cfg.ppo.kl_actions}"
        if cfg.ppo.assist_in_ratio != PPOConfig().assist_in_ratio:
            name += f" ratio:{cfg.ppo.assist_in_ratio}"
    task = resolve_task(cfg)
    ppo_passes = cfg.ppo.num_learning_epochs or task.learning_epochs
    encoder_passes = cfg.model.vae_learning_epochs or ppo_passes  # 0: PPO's passes
    default = (task.learning_epochs, task.vae_learning_epochs or task.learning_epochs)
    if (ppo_passes, encoder_passes) != default:
        name += f" update:{ppo_passes}+{encoder_passes}"
    if cfg.task_overrides:
        late = dict(_flat(branched_from["overrides"])) if branched_from else {}
        name += " task:" + ",".join(
            f"{field}={_compact(value)}" + (f"@{branched_from['iteration']}" if field in late else "")
            for field, value in _flat(cfg.task_overrides)
        )  # fmt: skip
    return name


def _flat(overrides: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """``{"a": {"b": 1}, "c.d": 2}`` -> ``[("a.b", 1), ("c.d", 2)]`` (dotted fields, sorted)."""
    items: list[tuple[str, Any]] = []
    for key, value in overrides.items():
        if isinstance(value, dict) and value:
            items += _flat(value, f"{prefix}{key}.")
        else:
            items.append((f"{prefix}{key}", value))
    return sorted(items)


def _compact(value: Any) -> str:
    """A value as short text (no spaces: a group name is split on them)."""
    if isinstance(value, float):
        return f"{value:g}"
    return json.dumps(value, separators=(",", ":")).replace(" ", "_")


def _curriculum_variant(cur: Any) -> str:
    """``+paper``, or the skill trigger and the schedule where they differ from the default."""
    from rl.a2cf.config import PAPER_RULES, CurriculumConfig

    name, default = "", CurriculumConfig()
    if all(getattr(cur, key) == value for key, value in PAPER_RULES.items()):
        return "+paper"
    trigger = (cur.skill_measure, cur.skill_learned_progress)
    if trigger != (default.skill_measure, default.skill_learned_progress):
        name += f" skill:{cur.skill_measure}@{cur.skill_learned_progress:g}"
    if cur.anneal_iterations != default.anneal_iterations:
        name += f" anneal:{cur.anneal_iterations or 'off'}"
    return name


def summarise_study(run_dirs: list[str | Path], out: str | Path) -> dict[str, Any]:
    """Per run and per (task, mode): env steps to the assistance-free target (mean, spread over
    seeds, runs that never reached it counted as not reached); ``study.json`` and ``study.png``
    (survival and the task metric against env steps) in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = [run_summary(d) for d in run_dirs]
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in runs:
        groups[f"{r['task']} {r['variant']}"].append(r)
    table = []
    for name, members in groups.items():
        reached = [m["reached_at_env_steps"] for m in members if m["reached_at_env_steps"]]
        confirmed = [m for m in members if m["reached_at_env_steps"] and m["confirmed"]]
        table.append(
            {
                "group": name,
                "seeds": [m["seed"] for m in members],
                "reached": f"{len(reached)}/{len(members)}",
                "confirmed": f"{len(confirmed)}/{len(members)}",
                "env_steps_to_target_mean": float(np.mean(reached)) if reached else None,
                "env_steps_to_target_std": float(np.std(reached)) if reached else None,
                "env_steps_to_target": [m["reached_at_env_steps"] for m in members],
                "env_steps_to_confirmed_pair": [m["confirmed_pair_at_env_steps"] for m in members],
                "evaluated_env_steps": [m["evaluated_env_steps"] for m in members],
                "last_survival": [m["last_survival"] for m in members],
                "last_metric": [m["last_metric"] for m in members],
            }
        )
    # each group's reference: the baseline of its task with the same update
    baselines = {_reference(r["group"]): r for r in table if r["group"].split()[1] == "baseline"}
    for row in table:
        base = baselines.get(_reference(row["group"]))
        mean, ref = row["env_steps_to_target_mean"], base and base["env_steps_to_target_mean"]
        # Ratio of the mean env steps to the target over the seeds that reached it (the
        # "reached" column says how many); None when either side never reached it.
        row["ratio_to_baseline"] = mean / ref if mean and ref else None
    result = {"runs": runs, "groups": table}
    atomic_write_json(out / "study.json", result)
    _plot([Path(d) for d in run_dirs], runs, out / "study.png")
    return result


def _reference(group: str) -> tuple[str, str, str]:
    """A group's task, update label (``update:...``, empty for the task's own update) and task
    changes (``task:...``): a run's baseline is the one on the same recipe."""
    words = group.split()
    labels = [next((w for w in words if w.startswith(p)), "") for p in ("update:", "task:")]
    return words[0], labels[0], labels[1]


def _plot(run_dirs: list[Path], runs: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = sorted({r["metric"] for r in runs if r["metric"]})
    fig, axes = plt.subplots(1, 1 + len(metrics), figsize=(5 * (1 + len(metrics)), 3.8))
    axes = np.atleast_1d(axes)
    for run_dir, run in zip(run_dirs, runs, strict=True):
        rows = read_evals(run_dir)
        label = f"{run['run']} ({run['num_envs']} envs)"
        x, y = curve_arrays(rows, "survival_fraction")
        axes[0].plot(x / 1e6, y, marker=".", label=label)
        if run["metric"]:
            ax = axes[1 + metrics.index(run["metric"])]
            x, y = curve_arrays(rows, run["metric"])
            ax.plot(x / 1e6, y, marker=".", label=label)
    axes[0].set_ylabel("survival alone (assistance off)")
    axes[0].set_ylim(-0.02, 1.02)
    for ax, metric in zip(axes[1:], metrics, strict=True):
        ax.set_ylabel(metric)
        bound = next(r["max_metric"] for r in runs if r["metric"] == metric)
        ax.axhline(bound, color="k", ls="--", lw=0.8)
    for ax in axes:
        ax.set_xlabel("env steps [M]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path, dpi=100)
    plt.close(fig)


def lifecycle_figure(run_dirs: list[str | Path], path: str | Path, title: str = "") -> Path:
    """The A2CF lifecycle of runs against env steps, one figure: the bound ``|eta|`` (the largest
    phase's), the applied force, the helped and the alone envs' skill progress during training,
    and the motion policy's evaluations alone (survival; the task metric). Baseline runs appear
    in the last panels only."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 5, figsize=(24, 4.2))
    metric_name = None
    colors = plt.get_cmap("tab10" if len(run_dirs) <= 10 else "tab20")
    for index, run_dir in enumerate(map(Path, run_dirs)):
        summary = run_summary(run_dir)
        label = f"{summary['variant']} s{summary['seed']}"
        metric_name = metric_name or summary["metric"]
        rows = read_metric_rows(run_dir)
        steps = np.cumsum([r["env_steps"] for r in rows]) / 1e6
        color = colors(index % colors.N)
        if summary["mode"] != "baseline" and rows:
            eta = [max(r["eta_norm"]) if r["eta_norm"] else 0.0 for r in rows]
            axes[0].plot(steps, eta, color=color, label=label)
            axes[1].plot(steps, [r["applied_force_n"] for r in rows], color=color, label=label)
            axes[2].plot(steps, [r["skill_progress"] or 0.0 for r in rows], color=color,
                         label=f"{label} helped")  # fmt: skip
            alone = [r.get("skill_progress_alone") for r in rows]
            if any(a is not None for a in alone):
                axes[2].plot(steps, [a or 0.0 for a in alone], color=color, ls=":",
                             label=f"{label} alone envs")  # fmt: skip
        evals = read_evals(run_dir)
        x, y = curve_arrays(evals, "survival_fraction")
        axes[3].plot(x / 1e6, y, marker=".", color=color, label=label)
        if summary["metric"]:
            x, y = curve_arrays(evals, summary["metric"])
            axes[4].plot(x / 1e6, y, marker=".", color=color, label=label)
            axes[4].axhline(summary["max_metric"], color="k", ls="--", lw=0.8)
    axes[0].set_ylabel("|eta| of the largest phase [N, Nm]")
    axes[1].set_ylabel("applied force, mean |F| [N]")
    axes[2].set_ylabel("skill progress in training (1 = target)")
    axes[3].set_ylabel("policy alone (evaluations): survival")
    axes[3].set_ylim(-0.02, 1.02)
    axes[4].set_ylabel(f"policy alone: {metric_name}" if metric_name else "(no task metric)")
    for ax in axes:
        ax.set_xlabel("env steps [M]")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    atomic_savefig(fig, path, dpi=90)
    plt.close(fig)
    return path
