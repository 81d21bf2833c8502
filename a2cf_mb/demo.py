"""``a2cf-mb demo``: the whole method end to end, small enough for a 2-core laptop.

1. The oracle: ``solve-walk`` (placo walk -> per-frame wrench QP over an alpha sweep -> eta0 per
   phase -> artifact with plots and video).
2. Training, same seed, envs and budget: the baseline (no assist agent) and A2CF with the force
   agent warm-started from a coach (``--warmstart``: the task's oracle artifact when its task is
   the training task, else the built-in as-needed posture coach, with the paper's bounds).
3. Evaluation of both motion policies alone (assistance off), in the training physics and in the
   second simulator (``eval --sim2sim``), with a video each when rendering works.
4. ``report.md`` with the figures, the numbers and what the small budget can and cannot show.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from optimal_control.files import atomic_savefig, atomic_write_text, check_writable_dir
from rl.run_folder import METRICS_FILE, WARMSTART_FILE


@dataclass(frozen=True)
class DemoConfig:
    """Budget and outputs of the demo (bigger budgets are flags)."""

    task: str = "stand"  # training task (see list-tasks)
    num_envs: int = 64  # parallel envs of each training run [-]
    iterations: int = 200  # PPO iterations of each run (24 steps per env each) [-]
    seed: int = 0  # seed of both runs [-]
    walk_duration_s: float = 4.0  # length of the oracle's walk reference [s]
    eval_envs: int = 16  # envs of each evaluation [-]
    video: bool = True  # eval videos (needs MUJOCO_GL=egl; skipped with a note otherwise)
    out: str = "demo"  # output folder (report.md, oracle/, runs/) [-]
    overwrite: bool = False  # replace an existing output folder

    def __post_init__(self) -> None:
        """Check sizes before any work (the walk's bound is the oracle's own)."""
        from optimal_control.validation import require_within
        from optimal_control.walk import MAX_WALK_DURATION_S

        if min(self.num_envs, self.iterations, self.eval_envs) < 1:
            raise ValueError("demo num_envs, iterations and eval_envs must be >= 1")
        require_within(
            self, "walk_duration_s", 0.0, MAX_WALK_DURATION_S, "s", low_open=True,
            why="the oracle's walk repeats one step cycle (see a2cf-mb solve-walk --duration)",
        )  # fmt: skip


def _eta_table(eta0: list[list[float]], phases: list[str]) -> str:
    lines = ["| phase | fx | fy | fz [N] | mx | my | mz [N m] |", "|---|---|---|---|---|---|---|"]
    for name, row in zip(phases, eta0, strict=True):
        lines.append(f"| {name} | " + " | ".join(f"{v:.1f}" for v in row) + " |")
    return "\n".join(lines)


def _curves(runs: dict[str, Path], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for name, run in runs.items():
        rows = json.loads((run / METRICS_FILE).read_text())["iterations"]
        steps, total = [], 0
        for r in rows:
            total += r["env_steps"]
            steps.append(total)
        axes[0].plot(steps, [r["mean_episode_length"] or 0.0 for r in rows], label=name)
        axes[1].plot(steps, [r["mean_step_reward"] for r in rows], label=name)
        axes[2].plot(steps, [r["applied_force_n"] for r in rows], label=name)
    titles = ("mean episode length [steps]", "mean step reward", "applied assist force [N]")
    for ax, title in zip(axes, titles, strict=True):
        ax.set_title(title)
        ax.set_xlabel("env steps")
        ax.legend()
    fig.tight_layout()
    path = out / "learning_curves.png"
    atomic_savefig(fig, path, dpi=100)
    plt.close(fig)
    return path


def run_demo(cfg: DemoConfig = DemoConfig()) -> Path:
    """Run the demo; returns the path of ``report.md``."""
    from optimal_control.oracle import OracleConfig, solve_walk
    from optimal_control.walk import WalkConfig
    from rl.envs.config import EnvConfig
    from rl.evaluate import EvalConfig, evaluate
    from rl.registry import get_task
    from rl.runner import train
    from rl.train_config import TrainConfig

    out = Path(cfg.out)
    if out.exists() and any(out.iterdir()):
        if not cfg.overwrite:
            raise ValueError(f"demo output folder {out} exists: pass --overwrite or another --out")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out, "demo --out")
    task = get_task(cfg.task)
    times: dict[str, float] = {}

    start = time.time()
    oracle_dir = out / "oracle"
    artifact, _ = solve_walk(
        WalkConfig(duration=cfg.walk_duration_s),
        OracleConfig(out=str(oracle_dir), progress=False, video=cfg.video),
    )
    times["oracle"] = time.time() - start
    warmstart = str(oracle_dir) if artifact.task == task.name else "posture"

    common = TrainConfig(
        task=cfg.task, iterations=cfg.iterations, out=str(out / "runs"),
        env=EnvConfig(num_envs=cfg.num_envs, seed=cfg.seed), save_interval=cfg.iterations,
    )  # fmt: skip
    specs = {
        "baseline": dataclasses.replace(common, mode="baseline", run_name="baseline"),
        "a2cf_warmstart": dataclasses.replace(
            common, mode="a2cf", warmstart=warmstart, run_name="a2cf_warmstart"
        ),
    }
    runs: dict[str, Path] = {}
    evals: dict[str, dict[str, Any]] = {}
    for name, train_cfg in specs.items():
        start = time.time()
        runs[name] = train(train_cfg, verbose=False).run_dir
        times[f"train {name}"] = time.time() - start
        start = time.time()
        video = str(out / f"{name}.mp4") if cfg.video else ""
        evals[name] = evaluate(
            runs[name], EvalConfig(num_envs=cfg.eval_envs, video=video, sim2sim=True)
        )
        times[f"eval {name}"] = time.time() - start
    curves = _curves(runs, out)
    report = _report(cfg, artifact, oracle_dir, warmstart, runs, evals, curves, times)
    path = out / "report.md"
    atomic_write_text(path, report)
    return path


def _report(cfg, artifact, oracle_dir, warmstart, runs, evals, curves, times) -> str:
    warm = json.loads((runs["a2cf_warmstart"] / WARMSTART_FILE).read_text())
    fit = warm["held_out_fit"]
    rows = [
        f"| {name} | {e['survival_fraction']:.2f} | {e['mean_return']:.2f} | "
        f"{e['sim2sim']['survival_fraction']:.2f} | {e['sim2sim']['mean_return']:.2f} |"
        for name, e in evals.items()
    ]
    env_steps = cfg.iterations * cfg.num_envs * 24
    plots = sorted(p.name for p in (oracle_dir / "plots").glob("*.png"))
    videos = [f"- [{n}]({n}.mp4)" for n in evals if (Path(cfg.out) / f"{n}.mp4").is_file()]
    return "\n".join(
        [
            f"# a2cf-mb demo: task `{cfg.task}`",
            "",
            "## 1. The oracle (walk reference, wrench QP, eta0)",
            f"Artifact `oracle/` ({time_str(times['oracle'])}): novice model "
            f"`{artifact.novice_model}`; eta0 per phase from the alpha = {artifact.rule.novice_alpha} "
            "profile:",
            "",
            _eta_table(artifact.eta0.tolist(), list(artifact.phase_names)),
            "",
            *[f"![{p}](oracle/plots/{p})" for p in plots],
            "",
            "## 2. Training (same seed, envs and budget)",
            f"{cfg.num_envs} envs x 24 steps x {cfg.iterations} iterations = {env_steps} env steps "
            f"per run; baseline {time_str(times['train baseline'])}, A2CF + warm start "
            f"{time_str(times['train a2cf_warmstart'])}. Warm start: {warm['coach']} "
            f"(`--warmstart {warmstart}`); held-out fit of the distilled head, R^2 mx "
            f"{fit['mx']['r2']:.2f}, my {fit['my']['r2']:.2f}, fz {fit['fz']['r2']:.2f}; the coach "
            f"helps in {100 * warm['share_of_states_helped']:.0f} % of the visited states.",
            "",
            "![learning curves](learning_curves.png)",
            "",
            "## 3. Evaluation, assistance off",
            "| run | survival (training physics) | return | survival (sim2sim) | return (sim2sim) |",
            "|---|---|---|---|---|",
            *rows,
            "",
            *videos,
            "",
            "## What this budget shows",
            f"{env_steps} env steps per run is a smoke-scale budget (the paper trains walking for "
            "~10^9 steps on a GPU): it shows the pipeline end to end and the first trend of the "
            "curves, not a converged skill or a significant difference between the methods. Bigger "
            "budgets: `a2cf-mb demo --iterations 500 --num-envs 256`; the measured comparisons are in "
            "docs/training.md and docs/results/.",
            "",
        ]
    )


def time_str(seconds: float) -> str:
    """``12 s`` / ``3.4 min``."""
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"
