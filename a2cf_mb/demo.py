"""``a2cf-mb demo``: learned skills first, then one learning story end to end on 2 CPU cores.

0. The zoo: each learned skill's bundle played (``a2cf-mb play``), a video and a contact sheet.
1. For the dance only, the oracle: ``a2cf-mb solve-dance`` (the built-in choreography -> per-frame
   wrench QP over an alpha sweep -> eta0 -> artifact with plots) into ``<out>/oracle/``.
2. Two training runs side by side, one per core, same seed, envs and budget: ``baseline`` (no
   assist agent) and ``a2cf_warm`` (A2CF, its force agent warm-started from the story's coach:
   the posture coach for ``stand``, the oracle's for ``dance``, plus :data:`A2CF_VARIANT_FLAGS`).
   Both evaluate their policy alone (assistance off) ``DemoConfig.evals`` times during training.
3. As each run ends, its motion policy is evaluated alone in the training physics and in the
   second simulator (``a2cf-mb eval --sim2sim``), with a video when rendering works.
4. ``summary.json`` (the numbers) and ``report.md`` (the figures, the numbers and what they show).

The default story is ``stand`` (standing under pushes), the one skill whose target a policy alone
reaches within the demo's budget; ``--task dance`` tells the dance's, which does not get there in
that budget (docs/results/track_learn).

Every stage is a child process (``python -m a2cf_mb ...``, one thread each) logging to
``<out>/logs/``; the terminal shows each training run's iteration, env steps, episode length,
assist bound and ETA while it runs (:mod:`a2cf_mb.progress`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shlex
import shutil
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from a2cf_mb.demo_report import (
    A2CF,
    BASELINE,
    DEMO_ENTRIES,
    LOGS_DIR,
    ORACLE_DIR,
    REPORT_FILE,
    RUNS_DIR,
    SUMMARY_FILE,
    VIDEOS_DIR,
    ZOO_DIR,
    build_summary,
    oracle_entry,
    plot_curves,
    read_run,
    relative,
    render_report,
    verdict,
)
from a2cf_mb.play import JUDGE_FILE, write_png, zoo_skills
from a2cf_mb.play import ZOO_DIR as SKILLS_DIR
from a2cf_mb.progress import (
    Stage,
    StatusBoard,
    TrainFollower,
    clock_str,
    duration_str,
    format_alone,
    format_train_status,
    run_lanes,
)
from optimal_control.files import (
    OutputExistsError,
    atomic_write_json,
    atomic_write_text,
    check_writable_dir,
)
from rl.runs.folder import EVAL_FILE, METRICS_FILE, RunFolderLock, StaleLockWarning

ORACLE = "oracle"
"""A story's warm start that is the oracle solved first (``solve-dance``), not a built-in coach."""


@dataclass(frozen=True)
class Story:
    """What the demo's two runs learn: the task, the A2CF run's warm start (:data:`ORACLE` or a
    built-in coach, :data:`rl.a2cf.coaches.COACHES`), the update flags of both runs, and where its
    figures over seeds are measured."""

    task: str
    warmstart: str
    recipe_flags: tuple[str, ...]
    help_text: str  # what the A2CF run's force agent starts from (the report's section 1)
    study: str  # the study that measures the baseline on this target over seeds


STORIES: dict[str, Story] = {
    "stand": Story(
        task="stand",
        warmstart="posture",
        recipe_flags=(),
        help_text="the built-in posture coach: a PD on pelvis tilt and height beyond a tolerance "
        "band, its gains from the G1's mass and inertia (rl/a2cf/coaches.py), distilled into the "
        "force agent before PPO; the bound starts at the task's eta0 below",
        study="docs/results/stand_judge/README.md",
    ),
    "dance": Story(
        task="dance",
        warmstart=ORACLE,
        # 2 PPO passes and 1 encoder pass per rollout instead of dance's 5 and 5 (stand's
        # default): a shorter update that learns as fast per env step (docs/training.md)
        recipe_flags=("--ppo-num-learning-epochs", "2", "--model-vae-learning-epochs", "1"),
        help_text="the oracle's coach, distilled into the force agent before PPO; the bound "
        "starts at the oracle's eta0",
        study="docs/results/track_learn",
    ),
}
"""The demo's learning stories by task name (``--task``)."""
A2CF_VARIANT_FLAGS: tuple[str, ...] = ()
"""``a2cf-mb train`` flags of the A2CF run beyond ``--mode a2cf --warmstart <coach>``; the report
and summary.json print them. Empty: the default curriculum (the help gone after 200 iterations by
the fixed schedule, sooner where the helped skill holds 0.6 of its target; no force rule; a quarter
of the envs never helped; the learning rate set by the motion actions' KL; docs/training.md)."""


SEED_SPREAD_FILE = Path(__file__).resolve().parents[1] / "docs/results/track_learn/seed_spread.json"
"""The baseline's skill metric over seeds, at env-step budgets, measured by the study of
``docs/results/track_learn`` (its ``summarise.py`` writes it): what the demo's one-seed comparison
is read against."""
NUM_STEPS_PER_ENV = 24
"""Steps per env per iteration of the demo's runs (the trainer's default)."""


def seed_spread(env_steps: int) -> dict[str, Any] | None:
    """The measured seed spread nearest ``env_steps`` (within 25 %), or None (no study here, or
    none near the demo's budget)."""
    if not SEED_SPREAD_FILE.is_file():
        return None
    rows = json.loads(SEED_SPREAD_FILE.read_text())["budgets"]
    near = [r for r in rows if abs(r["env_steps"] - env_steps) <= 0.25 * env_steps]
    if not near:
        return None
    best = min(near, key=lambda r: abs(r["env_steps"] - env_steps))
    return {**best, "source": str(SEED_SPREAD_FILE.relative_to(SEED_SPREAD_FILE.parents[3]))}


@dataclass(frozen=True)
class DemoConfig:
    """Budget and outputs of ``a2cf-mb demo`` (the dance, oracle to evaluation)."""

    task: str = "stand"  # the story: stand (the target in budget) or dance [-]
    iterations: int = 480  # PPO iterations per run, num_envs x 24 env steps each [-]
    num_envs: int = 128  # parallel envs of each training run [-]
    seed: int = 0  # seed of both runs [-]
    evals: int = 10  # evaluations of each policy alone, the last at the end [-]
    eval_envs: int = 32  # envs of the final evaluations, one episode each [-]
    video: bool = True  # a video of each final evaluation (needs MUJOCO_GL=egl)
    zoo: bool = True  # first play the zoo's learned skills (needs --video)
    out: str = "demo"  # output folder: report.md, summary.json, runs/, ... [-]
    overwrite: bool = False  # replace the output folder of an earlier demo

    def __post_init__(self) -> None:
        """Check the story and sizes before any work."""
        if self.task not in STORIES:
            raise ValueError(f"demo --task {self.task!r}: choose one of {', '.join(STORIES)}")
        for name in ("iterations", "num_envs", "evals", "eval_envs"):
            if getattr(self, name) < 1:
                flag = "--" + name.replace("_", "-")
                raise ValueError(f"demo {flag} must be >= 1, got {getattr(self, name)}")

    @property
    def story(self) -> Story:
        """The learning story of :attr:`task`."""
        return STORIES[self.task]

    @property
    def eval_interval(self) -> int:
        """Iterations between two evaluations of the policy alone during training."""
        return max(math.ceil(self.iterations / self.evals), 1)


# ------------------------------------------------------------------------------------ commands
def train_arguments(cfg: DemoConfig, name: str, out: Path) -> list[str]:
    """``a2cf-mb`` arguments of training run ``name`` (:data:`BASELINE` or :data:`A2CF`)."""
    story = cfg.story
    common = [
        "train", "--task", story.task, "--iterations", str(cfg.iterations),
        "--num-envs", str(cfg.num_envs), "--seed", str(cfg.seed),
        "--torch-threads", "1", "--env-num-threads", "1",
        "--eval-interval", str(cfg.eval_interval), "--save-interval", str(cfg.iterations),
        "--out", str(out / RUNS_DIR), "--run-name", name, *story.recipe_flags,
    ]  # fmt: skip
    if name == BASELINE:
        return [*common, "--mode", "baseline"]
    warm = str(out / ORACLE_DIR) if story.warmstart == ORACLE else story.warmstart
    return [*common, "--mode", "a2cf", "--warmstart", warm, *A2CF_VARIANT_FLAGS]


def eval_arguments(cfg: DemoConfig, name: str, out: Path) -> list[str]:
    """``a2cf-mb`` arguments of the final evaluation of run ``name``."""
    video = ["--video", str(out / VIDEOS_DIR / f"{name}.mp4")] if cfg.video else []
    run_dir = str(out / RUNS_DIR / name)
    return ["eval", run_dir, "--num-envs", str(cfg.eval_envs), "--sim2sim", *video]


def oracle_arguments(out: Path) -> list[str]:
    """``a2cf-mb`` arguments of the oracle (no video: rendering the 17 s reference costs minutes
    on a CPU; ``a2cf-mb solve-dance`` renders it)."""
    return ["solve-dance", "--out", str(out / ORACLE_DIR), "--no-progress", "--no-video"]


def check_train_arguments(arguments: list[str]) -> None:
    """Parse ``a2cf-mb train`` arguments and build their config as the child will, so a bad flag
    (e.g. in :data:`A2CF_VARIANT_FLAGS`) fails in seconds, before any work."""
    from a2cf_mb.cli import build_parser
    from a2cf_mb.commands.train import task_overrides
    from a2cf_mb.config_cli import config_from_args
    from rl.tasks.registry import get_task
    from rl.training.config import TrainConfig

    args = build_parser("train").parse_args(arguments)
    overrides = task_overrides(args)
    config_from_args(TrainConfig, args, task_overrides=overrides)
    get_task(args.task).with_overrides(overrides)


def child_command(arguments: list[str]) -> list[str]:
    """The command line of a child: this Python, ``-m a2cf_mb`` and ``arguments``."""
    return [sys.executable, "-m", "a2cf_mb", *arguments]


def child_env() -> dict[str, str]:
    """The children's environment: one thread each (two runs share two cores), unbuffered
    output (their logs are read live), EGL for the videos unless MUJOCO_GL is set."""
    env = dict(os.environ)
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    env.setdefault("MUJOCO_GL", "egl")
    return env


# ------------------------------------------------------------------------------ output folder
def check_output(out: Path, overwrite: bool) -> None:
    """Refuse, before any work, an output folder the demo must not write: a file, an earlier
    output without ``overwrite``, a folder holding files the demo did not write, a run in it that
    a live process is training. Raises ValueError (OutputExistsError) or RunFolderBusyError."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"demo --out '{out}' is a file, not a folder; choose another --out")
    entries = sorted(p.name for p in out.iterdir()) if out.is_dir() else []
    if entries and not overwrite:
        raise OutputExistsError(
            f"demo --out '{out}' exists and is not empty; pass --overwrite to replace an earlier "
            "demo's output, or choose another --out"
        )
    foreign = [e for e in entries if e not in DEMO_ENTRIES]
    if foreign:
        raise ValueError(
            f"demo --out '{out}' holds files a demo does not write ({', '.join(foreign[:5])}); "
            "--overwrite deletes only an earlier demo's output: choose another --out"
        )
    runs = out / RUNS_DIR
    run_dirs = sorted(p for p in runs.iterdir() if p.is_dir()) if runs.is_dir() else []
    for run_dir in run_dirs:  # a live process training there: RunFolderBusyError naming it
        with warnings.catch_warnings():  # a stale lock (a stopped demo): deleted with the folder
            warnings.simplefilter("ignore", StaleLockWarning)
            with RunFolderLock(run_dir, create=False):
                pass


# ------------------------------------------------------------------------------------ the demo
def run_demo(cfg: DemoConfig = DemoConfig(), stream: IO[str] | None = None) -> Path:
    """Run the demo (see the module docstring); returns the path of ``report.md``.

    ``stream``: where the stage lines and the live status go (default stdout; redrawn in place
    when it is a terminal, a status block every 30 s otherwise).

    Raises:
        ValueError: a bad config, output folder or train flag (found before anything is written).
        a2cf_mb.progress.StageFailedError: a stage failed; its log's path and tail in the message.
    """
    from rl.tasks.registry import get_task

    out = Path(cfg.out).expanduser().absolute()
    check_output(out, cfg.overwrite)
    cfg = _without_video_where_none_can_be_made(cfg, stream)
    commands = {name: train_arguments(cfg, name, out) for name in (BASELINE, A2CF)}
    for arguments in commands.values():
        check_train_arguments(arguments)
    check_writable_dir(out, "demo --out")
    for entry in out.iterdir():  # an earlier demo's output (check_output made sure)
        if entry.is_dir():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    story = cfg.story
    task = get_task(story.task)
    board = StatusBoard(stream if stream is not None else sys.stdout)
    env = child_env()
    start = time.monotonic()
    coach = "the oracle" if story.warmstart == ORACLE else f"the {story.warmstart} coach"
    board.message(
        f"a2cf-mb demo: {story.task}, baseline vs A2CF warm-started from {coach}; {cfg.num_envs} "
        f"envs x {cfg.iterations} iterations per run, seed {cfg.seed}, one core each -> {out}"
    )
    times: dict[str, float] = {}
    zoo: dict[str, Any] = {}
    if cfg.zoo and cfg.video:  # the zoo is videos
        zoo = play_zoo(out, board, env)
    oracle = None
    if story.warmstart == ORACLE:
        times.update(run_lanes([[_oracle_stage(out)]], board, env))
        command = "a2cf-mb " + shlex.join(oracle_arguments(Path("OUT")))
        oracle = oracle_entry(out, command, times["oracle"])
    lanes = [
        _run_lane(cfg, name, arguments, out, task.target.metric)
        for name, arguments in commands.items()
    ]
    times.update(run_lanes(lanes, board, env))

    fall_error = getattr(task.skill, "fall_error_rad", None)
    summary = build_summary(
        story.task,
        config={
            **dataclasses.asdict(cfg),
            "eval_interval": cfg.eval_interval,
            "a2cf_variant_flags": list(A2CF_VARIANT_FLAGS),
            "recipe_flags": list(story.recipe_flags),
            "warmstart": story.warmstart,
            "help": story.help_text,
            "study": story.study,
            "eta0": [list(row) for row in task.assist_bound],
        },
        oracle=oracle,
        runs={
            name: read_run(
                out,
                name,
                arguments,
                times[f"train {name}"],
                times[f"eval {name}"],
                task.target.metric,
            )
            for name, arguments in commands.items()
        },  # fmt: skip
        target={
            "describe": task.target.describe(),
            "metric": task.target.metric,
            "max_metric": task.target.max_metric,
            "min_survival": task.target.min_survival,
            "fall_error": fall_error,
            "one_episode_of_the_mean": (fall_error or 1.0) / cfg.eval_envs,
            "episode_length_s": task.episode_length_s,
        },
        wall_time_s=time.monotonic() - start,
        seed_spread=seed_spread(cfg.iterations * cfg.num_envs * NUM_STEPS_PER_ENV)
        if story.task == "dance"
        else None,
    )
    summary["figure"] = plot_curves(out, summary)
    summary["zoo"] = zoo
    atomic_write_json(out / SUMMARY_FILE, summary)
    report = out / REPORT_FILE
    atomic_write_text(report, render_report(summary, out))
    board.message(
        f"demo done in {duration_str(summary['wall_time_s'])}: {report}, {out / SUMMARY_FILE}\n"
        + verdict(summary)
    )
    return report


def _without_video_where_none_can_be_made(cfg: DemoConfig, stream: IO[str] | None) -> DemoConfig:
    """``cfg``, with ``video`` off (and a line saying why) where no offscreen GL context can be
    made: the evaluations refuse ``--video`` up front there, and the figures matter more."""
    from optimal_control.render import RenderUnavailableError, check_offscreen_rendering

    if not cfg.video:
        return cfg
    try:
        check_offscreen_rendering()
    except RenderUnavailableError as err:
        print(f"a2cf-mb demo: no videos on this machine ({err}); figures only", file=stream)
        return dataclasses.replace(cfg, video=False)
    return cfg


def play_zoo(out: Path, board: StatusBoard, env: dict[str, str]) -> dict[str, Any]:
    """Stage 0: ``a2cf-mb play SKILL`` for every zoo skill, two lanes side by side, into
    ``<out>/zoo/`` (a video and a contact sheet each), then ``zoo.png``, every skill's sheet one
    above the other; returns per skill its video, sheet and judge figures (empty: no zoo)."""
    skills = zoo_skills()
    if not skills:
        board.message("[0/3] zoo: no learned skills installed (a2cf_mb/zoo/); skipped")
        return {}
    folder = out / ZOO_DIR
    folder.mkdir(parents=True, exist_ok=True)
    board.message(f"[0/3] zoo: the learned skills, played from their bundles: {', '.join(skills)}")

    def stage(skill: str) -> Stage:
        argv = ["play", skill, "--out", str(folder / f"{skill}.mp4")]
        return Stage(
            label=f"play {skill}",
            argv=child_command(argv),
            log=out / LOGS_DIR / f"play_{skill}.log",
            status=lambda t: f"{'play':<10} {clock_str(t):>7}  {skill}: rollout and video",
            done=lambda wall_s: (
                f"[0/3] play {skill}: {folder / f'{skill}.mp4'} ({duration_str(wall_s)})"
            ),
            start=f"[0/3] play {skill}: a2cf-mb {shlex.join(argv)}",
        )

    run_lanes([[stage(s) for s in skills[0::2]], [stage(s) for s in skills[1::2]]], board, env)
    import imageio.v3 as iio
    import numpy as np

    sheets = [iio.imread(folder / f"{s}.png") for s in skills]
    width = max(sheet.shape[1] for sheet in sheets)
    rows = [np.pad(s, ((0, 0), (0, width - s.shape[1]), (0, 0))) for s in sheets]
    write_png(folder / "zoo.png", np.concatenate(rows, axis=0))
    return {
        skill: {
            "video": relative(str(folder / f"{skill}.mp4"), out),
            "contact_sheet": relative(str(folder / f"{skill}.png"), out),
            "judge": json.loads((SKILLS_DIR / skill / JUDGE_FILE).read_text())
            if (SKILLS_DIR / skill / JUDGE_FILE).is_file()
            else None,
        }
        for skill in skills
    }


def _oracle_stage(out: Path) -> Stage:
    """Stage 1: ``a2cf-mb solve-dance`` into ``<out>/oracle``."""
    from optimal_control.artifact import OracleArtifact

    log = out / LOGS_DIR / "oracle.log"

    def done(wall_s: float) -> str:
        art = OracleArtifact.read_summary(out / ORACLE_DIR)
        bounds = "; ".join(
            f"{phase}: force [{', '.join(f'{v:.1f}' for v in row[:3])}] N, torque "
            f"[{', '.join(f'{v:.1f}' for v in row[3:])}] N m"
            for phase, row in zip(art.phase_names, art.eta0.tolist(), strict=True)
        )
        return f"[1/3] oracle: done in {duration_str(wall_s)}; eta0 {bounds}"

    return Stage(
        label="oracle",
        argv=child_command(oracle_arguments(out)),
        log=log,
        status=lambda t: f"{'oracle':<10} {clock_str(t):>7}  wrench QP along the dance reference",
        done=done,
        start=f"[1/3] oracle: a2cf-mb solve-dance -> {out / ORACLE_DIR} (log {log})",
    )


def _run_lane(
    cfg: DemoConfig, name: str, arguments: list[str], out: Path, metric: str
) -> list[Stage]:
    """Stages 2 and 3 of run ``name``: its training (live status from its log and run folder),
    then the evaluation of its policy alone."""
    run_dir = out / RUNS_DIR / name
    train_log = out / LOGS_DIR / f"train_{name}.log"
    eval_log = out / LOGS_DIR / f"eval_{name}.log"
    follower = TrainFollower(run_dir, cfg.iterations, warmstart=name == A2CF)

    def train_done(wall_s: float) -> str:
        m = json.loads((run_dir / METRICS_FILE).read_text())
        steps = sum(r["env_steps"] for r in m["iterations"])
        alone = format_alone(m.get("alone_last"), metric)
        return (
            f"[2/3] train {name}: done in {duration_str(wall_s)}, {m['iterations_done']} "
            f"iterations, {steps:,} env steps" + (f"; alone at the end: {alone}" if alone else "")
        )

    def eval_done(wall_s: float) -> str:
        e = json.loads((run_dir / EVAL_FILE).read_text())
        video = relative(e.get("video"), out) or e.get("video_note", "no video")
        return (
            f"[3/3] eval {name}: done in {duration_str(wall_s)}; alone: {format_alone(e, metric)} "
            f"(training physics), survival {e['sim2sim']['survival_fraction']:.0%} (sim2sim); "
            f"{video}"
        )

    what = "training physics, sim2sim" + (", video" if cfg.video else "")
    return [
        Stage(
            label=f"train {name}",
            argv=child_command(arguments),
            log=train_log,
            status=lambda t: format_train_status(name, follower.poll(), t, metric),
            done=train_done,
            start=f"[2/3] train {name}: a2cf-mb {shlex.join(arguments)} (log {train_log})",
        ),
        Stage(
            label=f"eval {name}",
            argv=child_command(eval_arguments(cfg, name, out)),
            log=eval_log,
            status=lambda t: f"{name:<10} {clock_str(t):>7}  evaluating alone: {what}",
            done=eval_done,
            start=f"[3/3] eval {name}: policy alone, {cfg.eval_envs} envs, {what} (log {eval_log})",
        ),
    ]
