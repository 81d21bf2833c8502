"""Live progress of child processes (the stages of ``a2cf-mb demo``).

Each child writes its stdout and stderr to a log file (the tail shown when it fails).
:class:`TrainFollower` reads a training run's progress from its run folder: the per-iteration
metrics rows the runner writes (``metrics.jsonl``: iterations done, total env steps, mean
episode length), the curriculum log's bound and applied force, the evaluations of the policy
alone; :func:`format_train_status` makes one line of it.
:class:`StatusBoard` shows one line per running child: redrawn in place every ``refresh_s`` on a
terminal, printed as a block every ``plain_interval_s`` otherwise (a log file, CI). :func:`run_lanes`
runs lanes of children side by side (each lane one child after the other) until all are done, or
stops them all when one fails and raises :class:`StageFailedError` with the tail of its log.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from rl.runs.folder import CONFIG_FILE, CURRICULUM_LOG, EVALS_LOG, METRICS_LOG, WARMSTART_FILE

ANSI_RE = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")
"""Terminal escape sequences (rsl-rl prints its header in bold), left out of a log's tail."""
INTERRUPT_GRACE_S = 10.0
"""After Ctrl-C, how long the children may take to end by themselves before they are stopped [s]."""


def clock_str(seconds: float) -> str:
    """``m:ss`` (``h:mm:ss`` from an hour on)."""
    s = max(int(round(seconds)), 0)
    h, rest = divmod(s, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


def duration_str(seconds: float) -> str:
    """``12 s`` / ``3.4 min`` / ``1.2 h``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def _last_json_line(path: Path, max_bytes: int = 65536) -> dict[str, Any] | None:
    """The last complete JSON line of ``path`` (None: missing, empty or not JSON yet)."""
    try:
        with path.open("rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(size - max_bytes, 0))
            lines = f.read().decode(errors="replace").splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            return json.loads(line)
        except ValueError:
            continue
    return None


@dataclass
class TrainSnapshot:
    """A training run's progress as its log and run folder show it now."""

    total: int  # iterations the run will do [-]
    completed: int = 0  # iterations done [-]
    env_steps: int = 0  # env steps PPO collected so far [-]
    mean_episode_length: float | None = None  # recent training episodes (helped ones too) [steps]
    bound_force_n: float | None = None  # force part of the assist bound, largest phase [N]
    bound_torque_nm: float | None = None  # torque part of the assist bound, largest phase [N m]
    applied_force_n: float | None = None  # mean applied assist force of the last iteration [N]
    alone: dict[str, Any] | None = None  # the last evaluation of the policy alone (evals.jsonl)
    eta_s: float | None = None  # estimated time to the last iteration [s]
    phase: str = "starting"  # starting | warm start | first iteration | training


class TrainFollower:
    """Follows one training run through its run folder.

    ``poll()`` reads the last lines of the run folder's metrics, curriculum and evaluation logs;
    the ETA comes from the iterations seen since the first one (so it includes the evaluations
    during training, and not the start-up).
    """

    def __init__(
        self,
        run_dir: Path,
        total: int,
        warmstart: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """Follow ``run_dir``, a run of ``total`` iterations (``warmstart``: it distils the
        assist head before its first iteration)."""
        self.run_dir = run_dir
        self.warmstart = warmstart
        self.clock = clock
        self.snapshot = TrainSnapshot(total=total)
        # (time, completed iterations) when the first iteration was seen: the ETA's reference
        self._first: tuple[float, int] | None = None

    def poll(self) -> TrainSnapshot:
        """Read what is new and return the snapshot."""
        snap = self.snapshot
        metrics = _last_json_line(self.run_dir / METRICS_LOG)
        if metrics is not None:
            snap.completed, snap.total = metrics["completed"], metrics["total_iterations"]
            snap.env_steps = metrics["total_env_steps"]
            snap.mean_episode_length = metrics.get("mean_episode_length")
        row = _last_json_line(self.run_dir / CURRICULUM_LOG)
        if row is not None and row.get("eta"):
            snap.bound_force_n = max(sum(v * v for v in r[:3]) ** 0.5 for r in row["eta"])
            snap.bound_torque_nm = max(sum(v * v for v in r[3:]) ** 0.5 for r in row["eta"])
            snap.applied_force_n = row.get("applied_force_n")
        alone = _last_json_line(self.run_dir / EVALS_LOG)
        if alone is not None:
            snap.alone = alone
        now = self.clock()
        if snap.completed == 0:
            if not (self.run_dir / CONFIG_FILE).is_file():
                snap.phase = "starting"
            elif self.warmstart and not (self.run_dir / WARMSTART_FILE).is_file():
                snap.phase = "warm start"
            else:
                snap.phase = "first iteration"
        else:
            snap.phase = "training"
            if self._first is None:
                self._first = (now, snap.completed)
            t0, c0 = self._first
            if snap.completed > c0:
                per_iteration_s = (now - t0) / (snap.completed - c0)
                snap.eta_s = per_iteration_s * (snap.total - snap.completed)
        return snap


def format_alone(row: dict[str, Any] | None, metric: str) -> str:
    """``survival 81%, skill_error_rad 0.247`` of an evaluation of the policy alone ('' if none)."""
    if row is None:
        return ""
    text = f"survival {row['survival_fraction']:.0%}"
    value = row.get("task_metrics", {}).get(metric)
    return text + (f", {metric} {value:.3f}" if isinstance(value, (int, float)) else "")


def format_train_status(name: str, snap: TrainSnapshot, elapsed_s: float, metric: str) -> str:
    """One status line of a training run, most important first (a narrow terminal cuts the end),
    e.g. ``a2cf_warm  3:12  120/320 it  368,640 env steps  ep len 82  bound 42 N 61 Nm  ETA 4:40
    alone@96: survival 0%, skill_error_rad 1.000``."""
    head = f"{name:<10} {clock_str(elapsed_s):>7}"
    if snap.completed == 0:
        what = {
            "starting": "starting: imports, env",
            "warm start": "warm start: distilling the assist head from its coach",
            "first iteration": "first iteration",
        }.get(snap.phase, snap.phase)
        return f"{head}  {what}"
    width = len(str(snap.total))
    parts = [
        f"{snap.completed:>{width}}/{snap.total} it",
        f"{snap.env_steps:>9,} env steps",
        "ep len " + (f"{snap.mean_episode_length:>3.0f}" if snap.mean_episode_length else "  -"),
    ]
    if snap.bound_force_n is not None:
        parts.append(f"bound {snap.bound_force_n:.0f} N {snap.bound_torque_nm:.0f} Nm")
    parts.append("ETA " + (clock_str(snap.eta_s) if snap.eta_s is not None else "-"))
    if snap.alone is not None:
        parts.append(f"alone@{snap.alone['iteration']}: {format_alone(snap.alone, metric)}")
    return f"{head}  " + "  ".join(parts)


class StatusBoard:
    """Status lines of the running children, and permanent messages above them.

    On a terminal the block of status lines is redrawn in place (at most every ``refresh_s``);
    elsewhere it is printed whole every ``plain_interval_s``, so a log file gets a line per run
    about every half minute. Messages (a stage started or ended) are printed at once in both.
    """

    def __init__(
        self,
        stream: IO[str] | None = None,
        tty: bool | None = None,
        refresh_s: float = 2.0,
        plain_interval_s: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """Write to ``stream`` (default stdout); ``tty`` None: ask the stream."""
        self.stream = stream if stream is not None else sys.stdout
        self.tty = self.stream.isatty() if tty is None else tty
        self.refresh_s = refresh_s
        self.plain_interval_s = plain_interval_s
        self.clock = clock
        self._drawn = 0  # lines of the block on screen (terminal)
        self._lines: list[str] = []
        self._last = clock()

    def _width(self) -> int:
        return shutil.get_terminal_size((120, 24)).columns - 1

    def _erase(self) -> None:
        if self._drawn:
            self.stream.write(f"\x1b[{self._drawn}F\x1b[J")
            self._drawn = 0

    def _draw(self) -> None:
        width = self._width()
        for line in self._lines:
            self.stream.write((line if len(line) <= width else line[: width - 1] + "~") + "\n")
        self._drawn = len(self._lines)
        self.stream.flush()

    def update(self, lines: Sequence[str]) -> None:
        """Set the status lines without drawing them (the next message or due show does)."""
        self._lines = list(lines)

    def show(self, lines: Sequence[str], force: bool = False) -> None:
        """Set the status lines; drawn now when due (or ``force``)."""
        self._lines = list(lines)
        now = self.clock()
        due = now - self._last >= (self.refresh_s if self.tty else self.plain_interval_s)
        if not (due or force) or not self._lines:
            return
        self._last = now
        if self.tty:
            self._erase()
            self._draw()
        else:
            for line in self._lines:
                self.stream.write(f"  {line}\n")
            self.stream.flush()

    def message(self, text: str) -> None:
        """Print a permanent line (above the status block on a terminal)."""
        if self.tty:
            self._erase()
            self.stream.write(text + "\n")
            self._draw()
        else:
            self.stream.write(text + "\n")
            self.stream.flush()

    def close(self) -> None:
        """Remove the status block (terminal)."""
        if self.tty:
            self._erase()
            self.stream.flush()
        self._lines = []


class StageFailedError(RuntimeError):
    """A child process ended with an error; the message names it, its exit code, its log and
    the log's last lines."""


@dataclass
class Stage:
    """One child process of a lane."""

    label: str  # e.g. "train baseline": in messages and errors
    argv: list[str]  # the command
    log: Path  # its stdout and stderr (the command is its first line)
    status: Callable[[float], str]  # status line while it runs, from its elapsed time [s]
    done: Callable[[float], str]  # message when it ended well, from its wall time [s]
    start: str = ""  # message when it starts; empty: "<label>: started (log <log>)"


def log_tail(path: Path, lines: int = 25) -> str:
    """The last ``lines`` lines of a log, without terminal escapes."""
    try:
        with path.open("rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(f.tell() - 16384, 0))
            text = f.read().decode(errors="replace")
    except OSError as err:
        return f"(log unreadable: {err})"
    return "\n".join(ANSI_RE.sub("", text).rstrip("\n").splitlines()[-lines:])


@dataclass
class _Running:
    stage: Stage
    lane: int  # index of its lane
    proc: subprocess.Popen
    log: IO[bytes]
    started: float


def _start(
    stage: Stage, lane: int, env: dict[str, str] | None, clock: Callable[[], float]
) -> _Running:
    stage.log.parent.mkdir(parents=True, exist_ok=True)
    log = stage.log.open("wb")
    log.write(f"$ {shlex.join(stage.argv)}\n".encode())
    log.flush()
    try:
        proc = subprocess.Popen(
            stage.argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env
        )
    except OSError:
        log.close()
        raise
    return _Running(stage, lane, proc, log, clock())


def _stop(running: list[_Running], grace_s: float = 0.0) -> None:
    """Stop the children still running: after ``grace_s`` for them to end by themselves, SIGTERM,
    then SIGKILL after 10 s."""
    deadline = time.monotonic() + grace_s
    for r in running:
        with contextlib.suppress(subprocess.TimeoutExpired):
            r.proc.wait(timeout=max(deadline - time.monotonic(), 0.0))
    for r in running:
        if r.proc.poll() is None:
            r.proc.terminate()
    for r in running:
        try:
            r.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            r.proc.kill()
            r.proc.wait()
        r.log.close()


@contextlib.contextmanager
def _exit_on_sigterm() -> Iterator[None]:
    """While children run: a SIGTERM to this process exits through ``finally`` blocks (which stop
    them) instead of ending it at once and leaving them running."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def exit_(signum: int, frame: object) -> None:
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, exit_)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def run_lanes(
    lanes: Sequence[Sequence[Stage]],
    board: StatusBoard,
    env: dict[str, str] | None = None,
    poll_s: float = 0.5,
    clock: Callable[[], float] = time.monotonic,
) -> dict[str, float]:
    """Run the lanes side by side, the stages of a lane one after the other; returns each stage's
    wall time [s] by label.

    Raises :class:`StageFailedError` when a stage exits non-zero (the others are stopped first,
    and no later stage starts). On any other exit (Ctrl-C included) the children still running
    are stopped; a SIGTERM to this process stops them too.
    """
    queues = [list(lane) for lane in lanes]
    running: list[_Running] = []
    times: dict[str, float] = {}
    with _exit_on_sigterm():
        try:
            _drive(queues, running, times, board, env, poll_s, clock)
        except KeyboardInterrupt:
            # Ctrl-C in a terminal reaches the children too: let them close their run folders
            # (checkpoint, lock) before they are stopped.
            _stop(running, grace_s=INTERRUPT_GRACE_S)
            raise
        finally:
            _stop(running)
            board.close()
    return times


def _drive(
    queues: list[list[Stage]],
    running: list[_Running],
    times: dict[str, float],
    board: StatusBoard,
    env: dict[str, str] | None,
    poll_s: float,
    clock: Callable[[], float],
) -> None:
    """The loop of :func:`run_lanes` (``running`` and ``times`` are updated in place)."""

    def start(stage: Stage, lane: int) -> None:
        board.message(stage.start or f"{stage.label}: started (log {stage.log})")
        running.append(_start(stage, lane, env, clock))

    def statuses() -> list[str]:
        return [r.stage.status(clock() - r.started) for r in running]

    for lane, queue in enumerate(queues):
        if queue:
            start(queue.pop(0), lane)
    while running:
        for r in [r for r in running if r.proc.poll() is not None]:
            running.remove(r)
            r.log.close()
            wall = clock() - r.started
            if r.proc.returncode != 0:
                raise StageFailedError(
                    f"{r.stage.label} failed (exit code {r.proc.returncode}) after "
                    f"{duration_str(wall)}; its log {r.stage.log} ends with:\n"
                    f"{log_tail(r.stage.log)}"
                )
            times[r.stage.label] = wall
            board.update(statuses())
            board.message(r.stage.done(wall))
            if queues[r.lane]:
                start(queues[r.lane].pop(0), r.lane)
        board.show(statuses())
        if running:
            time.sleep(poll_s)
