"""The run folder: its file names, the lock that lets one process at a time write it, where a
run starts in it (new folder, or resume from the newest readable checkpoint), and the one reader
of each kind of file it holds.

Every command that reads a run folder (``train --resume``, ``eval``, ``eval-curve``, ``compare``,
sim2sim) goes through :func:`load_checkpoint`, :func:`read_config_file` /
:func:`load_run_config`, :func:`read_run_json` and :func:`read_run_jsonl` (the ONNX file:
:class:`rl.agents.export.OnnxMotionPolicy`). A damaged file raises :class:`DamagedRunFileError`, whose
message names the file and what to do (``docs/faults.md``).

The names are defined here once; :mod:`rl.training.runner` (which writes a run folder, and re-exports them),
:mod:`rl.studies.compare`, :mod:`rl.evaluation.sim2sim`, :mod:`a2cf_mb.demo` and the benchmarks import them. This
module imports nothing heavy, so readers of a run folder need not load torch or the env (the
checkpoint choice imports torch when it runs).

:class:`RunFolderLock` holds ``<run folder>/run.lock`` while a run is trained or resumed. The file
is created with ``O_CREAT | O_EXCL`` (of two processes, exactly one creates it) and names its
holder: pid, host, start time and command line. A second process is refused with
:class:`RunFolderBusyError`, one line naming the holder and what to do. A lock whose holder is gone
(its pid is no longer alive on this host, or the pid now belongs to a later process) is stale: it
is taken over with a :class:`StaleLockWarning`. A lock written on another host cannot be checked
and is respected. The lock is removed when the run ends (or fails); a SIGKILL leaves it behind,
which the next run then recognises as stale.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import sys
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any, NoReturn

from optimal_control.files import process_alive, remove_stale_temp_files

if TYPE_CHECKING:
    from rl.training.config import TrainConfig

CONFIG_FILE = "config.json"
"""Resolved TrainConfig, the resolved task, env config, rsl-rl config and eta0."""
GIT_FILE = "git.json"
"""Git revision and dirty flag of the project."""
CHECKPOINT_DIR = "checkpoints"
"""Folder of ``last.pt`` and the kept ``model_<completed iterations>.pt``."""
LAST_CHECKPOINT = "last.pt"
"""The checkpoint written after every iteration (atomically); a resume starts from it."""
CURRICULUM_LOG = "curriculum.jsonl"
"""One line per curriculum update: bounds, applied wrench, switches."""
METRICS_FILE = "metrics.json"
"""Per-iteration figures and the run summary, written when the run ends."""
METRICS_LOG = "metrics.jsonl"
"""One line per iteration as it is checkpointed: the iteration's metrics row, ``completed``,
``total_iterations`` and ``total_env_steps`` (what progress displays read, live)."""
WARMSTART_FILE = "warmstart.json"
"""Report of the warm start (``--warmstart`` / ``--warmstart-motion``)."""
POLICY_FILE = "policy.onnx"
"""The exported motion policy."""
POLICY_BUNDLE_FILE = str(PurePath(POLICY_FILE).with_suffix(".json"))
"""The deployment bundle :func:`rl.agents.export.export_motion_policy` writes beside the ONNX file."""
EVAL_FILE = "eval.json"
"""Result of ``a2cf-mb eval``."""
EVENTS_GLOB = "events.out.tfevents*"
"""TensorBoard event files (rsl-rl's logger names them)."""
LOCK_FILE = "run.lock"
"""Present while a process writes the run folder (see :class:`RunFolderLock`)."""
EVALS_LOG = "evals.jsonl"
"""Evaluations of the motion policy alone during training, one JSON line each."""
CHECKPOINT_EVALS_LOG = "evals_checkpoints.jsonl"
"""``a2cf-mb eval-curve``'s evaluations of the kept checkpoints, one JSON line each."""
EVALS_DIR = "evals"
"""Folder of the task evaluator's latest figures from the evaluations during training."""

UNREADABLE_LOCK_GRACE_S = 10.0
"""An empty or unreadable lock younger than this belongs to a process still writing it; an older
one was left by a process killed between creating and writing it, and is stale [s]."""


class RunFolderBusyError(RuntimeError):
    """Another live process holds the run folder's lock (the CLI prints it in one line, exit 2)."""


class StaleLockWarning(UserWarning):
    """A lock left by a process that no longer runs was taken over."""


@dataclass(frozen=True)
class LockHolder:
    """What a lock file says about the process holding it."""

    pid: int  # process id on ``host``
    host: str  # host name of the process
    started_utc: str  # when the lock was taken, ISO 8601 UTC
    command: str  # the holder's command line (shortened)
    process: str | None = None  # boot id and start tick of ``pid`` (Linux); detects pid reuse

    def describe(self) -> str:
        """``pid 123 on host h since 2026-01-02 03:04:05 UTC (a2cf-mb train ...)``."""
        since = self.started_utc.replace("T", " ").removesuffix("Z")
        return f"pid {self.pid} on host {self.host} since {since} UTC ({self.command})"


def _torchrun_rank() -> int:
    """This process's rank in a ``torchrun`` job (0 outside one): only rank 0 writes the folder."""
    return int(os.environ.get("RANK", "0"))


def _process_identity(pid: int) -> str | None:
    """Boot id and start time (clock ticks since boot) of ``pid``: two processes that share a pid
    at different times have different identities. None where ``/proc`` cannot tell."""
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "; comm may hold spaces
    return f"{boot}:{fields[19]}"  # field 22 of proc(5): starttime


def _command_line() -> str:
    """This process's command line, shortened, as a person would recognise it."""
    argv0 = Path(sys.argv[0] if sys.argv and sys.argv[0] else "python")
    if argv0.name == "a2cf-mb" or argv0.parent.name == "a2cf_mb":  # script or python -m a2cf_mb
        name = "a2cf-mb"
    else:
        name = argv0.name if not argv0.name.startswith("-") else f"python {argv0.name}"
    text = " ".join([name, *sys.argv[1:]])
    return text if len(text) <= 120 else text[:117] + "..."


def _read_holder(path: Path) -> LockHolder | None:
    """The holder named in a lock file; None when it is empty or unreadable."""
    try:
        holder = LockHolder(**json.loads(path.read_text()))
    except (OSError, ValueError, TypeError):
        return None
    return holder if isinstance(holder.pid, int) and holder.pid > 0 else None


class RunFolderLock:
    """Exclusive right of this process to write ``run_dir`` (a context manager).

    Entering creates the folder where missing (``create``) and the lock file; leaving removes the
    lock, and the folders it created if nothing was written into them (a run that fails before
    its first file leaves no empty run folder). Under ``torchrun`` every process of the job trains
    into the same folder: rank 0 holds the lock for the job, the other ranks take none.

    Raises (on entering) :class:`RunFolderBusyError` when a live process holds the lock, and
    :class:`FileNotFoundError` when ``create`` is False and the folder does not exist.
    """

    def __init__(self, run_dir: str | Path, create: bool = True) -> None:
        """Lock ``run_dir``; ``create``: make the folder (and its parents) where missing."""
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / LOCK_FILE
        self.create = create
        self.holder: LockHolder | None = None  # this process's entry while held
        self._created: list[Path] = []  # folders made by acquire, innermost first

    def __enter__(self) -> RunFolderLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def acquire(self) -> None:
        """Take the lock (see the class docstring); a stale lock is taken over with a warning."""
        if _torchrun_rank() != 0:
            return  # a torchrun job: rank 0 holds the lock for all its processes
        if not self.run_dir.is_dir():
            if not self.create:
                raise FileNotFoundError(errno.ENOENT, "No such run folder", str(self.run_dir))
            missing = [p for p in (self.run_dir, *self.run_dir.parents) if not p.exists()]
            self._created = missing
            try:
                self.run_dir.mkdir(parents=True, exist_ok=True)
            except OSError:
                self.release()  # the parents made before the failure go too
                raise
        me = LockHolder(
            pid=os.getpid(),
            host=socket.gethostname(),
            started_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            command=_command_line(),
            process=_process_identity(os.getpid()),
        )
        data = json.dumps(asdict(me)).encode()
        for _ in range(3):  # a takeover can lose the race to another process; then it is refused
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                self._take_over_if_stale()
                continue
            try:
                os.write(fd, data)  # one write: a reader sees all of it or an empty file
                os.fsync(fd)
            finally:
                os.close(fd)
            self.holder = me
            return
        self._refuse(_read_holder(self.path))

    def release(self) -> None:
        """Remove the lock if this process still holds it, then the empty folders it made."""
        if self.holder is not None:
            if _read_holder(self.path) == self.holder:
                self.path.unlink(missing_ok=True)
            self.holder = None
        for folder in self._created:
            try:
                folder.rmdir()  # only succeeds when empty
            except OSError as err:
                if err.errno in (errno.ENOENT, errno.ENAMETOOLONG):
                    continue  # never made: the mkdir failed before it
                break
        self._created = []

    def _take_over_if_stale(self) -> None:
        """Remove the existing lock when its holder is gone, else raise RunFolderBusyError."""
        try:
            text = self.path.read_bytes()  # junk too: compared, never decoded
            age_s = time.time() - self.path.stat().st_mtime
        except FileNotFoundError:
            return  # released meanwhile: try to create it again
        holder = _read_holder(self.path)
        if holder is None:
            if age_s < UNREADABLE_LOCK_GRACE_S:
                self._refuse(None)
            reason = f"an unreadable lock {age_s:.0f} s old"
        else:
            reason = self._stale_reason(holder)
            if reason is None:
                self._refuse(holder)
        # Move the lock aside and check it is the one judged stale: of two processes taking over
        # the same stale lock, the second must not delete the lock the first has just created.
        aside = self.path.with_name(f".{LOCK_FILE}.stale-{os.getpid()}")
        try:
            os.rename(self.path, aside)
        except FileNotFoundError:
            return
        if aside.read_bytes() != text:
            with contextlib.suppress(FileExistsError):
                os.link(aside, self.path)  # put the other process's fresh lock back
            aside.unlink()
            return
        aside.unlink()
        warnings.warn(
            f"{self.path} was left by {reason}; taking the run folder over",
            StaleLockWarning,
            stacklevel=4,
        )

    @staticmethod
    def _stale_reason(holder: LockHolder) -> str | None:
        """Why the holder is gone (None: it runs, or it runs on another host and cannot be
        checked)."""
        if holder.host != socket.gethostname():
            return None
        if not process_alive(holder.pid):
            return f"pid {holder.pid}, which no longer runs"
        now = _process_identity(holder.pid)
        if holder.process is not None and now is not None and now != holder.process:
            return f"pid {holder.pid}, which has ended (the pid now belongs to another process)"
        return None

    def _refuse(self, holder: LockHolder | None) -> NoReturn:
        who = holder.describe() if holder else "a process that is creating its lock right now"
        raise RunFolderBusyError(
            f"run folder {self.run_dir} is being written by {who}: one process at a time may "
            "write a run folder; wait for that run to end or stop it, or write into another "
            f"folder (--run-name, --out); if that process has ended, delete {self.path}"
        )


# ------------------------------------------------------------------ create, resume, checkpoint
def new_run_dir(cfg: TrainConfig) -> Path:
    """The folder of a new run: ``<out>/<run name>`` (by default task, mode and UTC time)."""
    name = cfg.run_name or f"{cfg.task}_{cfg.mode}_{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    return Path(cfg.out) / name


def require_unused(run_dir: Path) -> None:
    """Refuse a new run in a folder that already holds one."""
    if (run_dir / CONFIG_FILE).exists():
        raise FileExistsError(
            f"run folder {run_dir} already holds a run: pick another --run-name or use --resume"
        )


FIELDS_ADDED_LATER: dict[tuple[str, str], Any] = {
    ("curriculum", "anneal_iterations"): 0,  # no fixed schedule before it (default 200 since)
    ("model", "vae_learning_epochs"): 0,  # the encoder made PPO's passes before the option
    ("ppo", "kl_actions"): "all",  # the joint action's KL before the option
    ("ppo", "assist_in_ratio"): "always",  # the joint action in PPO's ratio before the option
}
"""``TrainConfig`` fields added after runs were made, with the value those runs trained with: a
config without the field is read with it (a resume continues as it began)."""


class DamagedRunFileError(ValueError):
    """A file of a run folder is truncated, empty or not what it should hold; the message names
    the file and what to do (the CLI prints it in one line, exit code 2)."""


def short_reason(err: BaseException) -> str:
    """The first sentence of an exception's message, short enough for a one-line error."""
    lines = str(err).strip().splitlines()
    text = lines[0].split(". ", 1)[0] if lines else type(err).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def read_run_json(path: Path, what: str, advice: str) -> Any:
    """The JSON value of run-folder file ``path`` (``what`` it holds, for the message). A file
    that is not valid JSON raises :class:`DamagedRunFileError` naming it and ``advice`` (what to
    do); a missing one the plain FileNotFoundError (callers say what its absence means)."""
    try:
        return json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as err:  # JSONDecodeError is a ValueError
        raise DamagedRunFileError(
            f"{path} ({what}) is damaged, not valid JSON ({short_reason(err)}): {advice}"
        ) from err


def read_run_jsonl(path: Path, what: str, advice: str) -> list[Any]:
    """The rows of a JSON-lines run-folder file (blank lines skipped); a damaged line raises
    :class:`DamagedRunFileError` naming the file, the line and ``advice``."""
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError as err:
        raise DamagedRunFileError(
            f"{path} ({what}) is damaged ({short_reason(err)}): {advice}"
        ) from err
    rows = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except ValueError as err:
            raise DamagedRunFileError(
                f"{path} ({what}) is damaged at line {number} ({short_reason(err)}): {advice}"
            ) from err
    return rows


CHECKPOINT_ADVICE = (
    "restore it from a backup, or delete it (a resume and `eval --no-use-onnx` then use the "
    "newest readable checkpoint, `eval-curve` skips it)"
)
"""What to do about a damaged checkpoint (the messages of :func:`load_checkpoint`)."""


def load_checkpoint(path: Path, map_location: Any = "cpu", advice: str = CHECKPOINT_ADVICE) -> dict:
    """The state saved in checkpoint ``path`` (``torch.load``). A file torch cannot read (a
    truncated zip, a foreign pickle, an empty file) or that is not a run checkpoint raises
    :class:`DamagedRunFileError` naming it and ``advice``; a missing one FileNotFoundError."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(errno.ENOENT, "No such checkpoint", str(path))
    try:
        state = torch.load(path, weights_only=False, map_location=map_location)
    except Exception as err:  # any unreadable file: torch raises RuntimeError, EOFError, ...
        raise DamagedRunFileError(
            f"checkpoint {path} cannot be read ({type(err).__name__}: {short_reason(err)}); it is "
            f"truncated or not a checkpoint: {advice}"
        ) from err
    if not isinstance(state, dict) or "completed_iterations" not in state:
        raise DamagedRunFileError(
            f"{path} is not a checkpoint of `a2cf-mb train` (no completed_iterations): {advice}"
        )
    return state


REEXPORT_ADVICE = (
    "export it again from the last checkpoint with `a2cf-mb train --resume {run_dir}` (a finished "
    "run only exports), or evaluate the checkpoint with `a2cf-mb eval --no-use-onnx {run_dir}`"
)
"""What to do about a damaged or missing ``policy.onnx`` (``{run_dir}``: the run folder)."""

CONFIG_ADVICE = "restore it from a backup, or start a new run"
"""What to do about a damaged ``config.json``."""


def read_config_file(run_dir: str | Path, sections: tuple[str, ...] = ("train",)) -> dict:
    """The saved ``config.json`` of a run folder, every section (``train``, ``task``, ``env``,
    ``rsl_rl``, ``eta0``); one clear error naming the file for a missing file, invalid JSON or
    a missing one of ``sections``."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        held = [
            name
            for name in (CHECKPOINT_DIR, METRICS_LOG, METRICS_FILE, POLICY_FILE)
            if (Path(run_dir) / name).exists()
        ]
        if Path(run_dir).is_file():  # a checkpoint or policy file given for its folder
            raise FileNotFoundError(
                f"'{run_dir}' is a file, not a run folder: give the folder `a2cf-mb train` wrote "
                f"(for a file inside a run, e.g. {CHECKPOINT_DIR}/{LAST_CHECKPOINT}, its run "
                "folder above it)"
            )
        if held:  # a run's files without its config: nothing can rebuild its env or networks
            raise FileNotFoundError(
                f"{path} not found, but '{run_dir}' holds a run's files ({', '.join(held)}): "
                f"restore {CONFIG_FILE} from a backup (no command can read the run without "
                "it), or start a new run"
            )
        folder = Path(run_dir)
        left = sorted(e.name for e in folder.iterdir()) if folder.is_dir() else []
        if left and all(n in (LOCK_FILE, "git") or n.startswith("events.out") for n in left):
            raise FileNotFoundError(  # a new run stopped before its config: nothing to resume
                f"{path} not found: '{run_dir}' holds no run yet ({', '.join(left)}: a new run "
                "stopped before it wrote its config); start it again with the same `a2cf-mb "
                "train ... --run-name` command, or delete the folder"
            )
        raise FileNotFoundError(
            f"{path} not found: '{run_dir}' is not a run folder made by `a2cf-mb train`"
        )
    try:
        saved = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as err:  # JSONDecodeError is a ValueError
        raise DamagedRunFileError(
            f"{path} is not a valid run config, not valid JSON ({short_reason(err)}): "
            f"{CONFIG_ADVICE}"
        ) from err
    missing = [
        name
        for name in sections
        if not isinstance(saved, dict) or not isinstance(saved.get(name), dict)
    ]
    if missing:
        found = sorted(saved) if isinstance(saved, dict) else type(saved).__name__
        raise DamagedRunFileError(
            f"{path} is not a valid run config: no {' or '.join(repr(m) for m in missing)} "
            f"section (found {found}); {CONFIG_ADVICE}"
        )
    return saved


def load_run_config(run_dir: str | Path) -> TrainConfig:
    """The TrainConfig saved in a run folder (clear errors for a missing or broken file: the file,
    and the section or fields that are wrong)."""
    from rl.training.config import TrainConfig

    path = Path(run_dir) / CONFIG_FILE
    data = read_config_file(run_dir)["train"]
    try:
        # a run made before a field existed keeps what it ran with, not today's default
        for (section, name), value in FIELDS_ADDED_LATER.items():
            if isinstance(data.get(section, {}), dict):
                data.get(section, {}).setdefault(name, value)
        return TrainConfig.from_dict(data)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise DamagedRunFileError(
            f"{path} is not a valid run config ({short_reason(err)}); {CONFIG_ADVICE}"
        ) from err


class RecipeChangedError(ValueError):
    """A run's checkpoint was trained on observations its task's recipe no longer has."""


def require_same_observations(run_dir: str | Path, task: Any) -> None:
    """Refuse, in one line, a run whose saved task read other observation terms than ``task``
    (today's recipe of it) does: its checkpoint's input layers would not fit. The run's
    ``git.json`` names the commit that can still load it. Runs saved without the task section
    are not checked."""
    try:
        saved = read_config_file(run_dir, ("train", "task"))["task"]["observations"]
        before = {g: [t["name"] for t in saved[g]["terms"]] for g in ("policy", "privileged")}
    except (DamagedRunFileError, FileNotFoundError, KeyError, TypeError):
        return
    now = {g: [t.name for t in getattr(task.observations, g).terms] for g in before}
    changed = [g for g in before if before[g] != now[g]]
    if changed:
        g = changed[0]
        raise RecipeChangedError(
            f"{run_dir} was trained on task '{task.name}' when its {g} observation read "
            f"{before[g]}; today's '{task.name}' reads {now[g]} (its recipe changed since: "
            f"docs/environments.md), so the run's checkpoints do not fit it. Check out the "
            f"commit named in {Path(run_dir) / 'git.json'} to evaluate or continue this run"
        )


def _recipe_leaves(node: Any, path: str = "") -> dict[str, Any]:
    """The scalar leaves of a saved task config by path; list items that have a ``name`` (terms)
    are keyed by it (``rewards[alive].weight``), so an added term is not a shift of the others."""
    if isinstance(node, dict):
        out: dict[str, Any] = {}
        for key, value in node.items():
            out.update(_recipe_leaves(value, f"{path}.{key}" if path else key))
        return out
    if isinstance(node, list) and node and all(isinstance(v, dict) and "name" in v for v in node):
        out = {f"{path}[{v['name']}]": "present" for v in node}
        for v in node:
            out.update(_recipe_leaves(v, f"{path}[{v['name']}]"))
        return out
    return {path: node}


def recipe_changes(run_dir: str | Path, task: Any) -> list[str]:
    """What of the run's saved task config ``task`` (today's recipe of it) has changed: each leaf
    both have that differs (``rewards[track_ang_vel_z].weight: 1.0 -> 2.0``) and each term one of
    them lacks. Fields added to the schema since the run began are not changes (the run had
    their default). Empty for a run saved without its task section."""
    try:
        saved = read_config_file(run_dir, ("train", "task"))["task"]
    except (DamagedRunFileError, FileNotFoundError):
        return []
    before, now = _recipe_leaves(saved), _recipe_leaves(task.to_json_dict())
    changes = [
        f"{k}: {before[k]!r} -> {now[k]!r}" for k in before if k in now and before[k] != now[k]
    ]
    changes += [f"{k}: removed" for k in before if k not in now and before[k] == "present"]
    changes += [f"{k}: added" for k in now if k not in before and now[k] == "present"]
    return changes


def _readable(path: Path) -> bool:
    try:
        load_checkpoint(path)
    except (DamagedRunFileError, OSError):
        return False
    return True


def newest_readable_checkpoint(
    run_dir: Path, command: str, doing: str, note: str = "", quiet: bool = False
) -> Path | None:
    """``checkpoints/last.pt``, or when it cannot be read (a disk fault: it is written atomically)
    the newest readable ``model_<k>.pt``, with a warning from ``command`` that it is ``doing``
    (``resuming``) from that one instead (``note``: what that means; ``quiet``: no warning);
    None when the run has no checkpoint. Only unreadable checkpoints:
    :class:`DamagedRunFileError` naming the folder."""
    folder = run_dir / CHECKPOINT_DIR
    last = folder / LAST_CHECKPOINT
    kept = sorted(
        folder.glob("model_*.pt"),
        key=lambda p: int(p.stem.split("_")[1]) if p.stem.split("_")[1].isdigit() else -1,
        reverse=True,
    )
    if not last.exists() and not kept:
        return None
    if last.exists() and _readable(last):
        return last
    for candidate in kept:
        if _readable(candidate):
            if quiet:
                return candidate
            print(
                f"{command}: warning: {last} cannot be read; {doing} from {candidate.name}, "
                f"the newest readable checkpoint{note}",
                file=sys.stderr,
            )
            return candidate
    raise DamagedRunFileError(
        f"no readable checkpoint in {folder} ({LAST_CHECKPOINT} and model_<k>.pt are damaged): "
        "restore one from a backup, or start a new run"
    )


def resumable_checkpoint(run_dir: Path, quiet: bool = False) -> Path | None:
    """The checkpoint a resume continues from (:func:`newest_readable_checkpoint`; iterations
    after a fallback checkpoint are redone)."""
    return newest_readable_checkpoint(
        run_dir, "a2cf-mb train", "resuming", " (later iterations are redone)", quiet=quiet
    )


def remove_unstarted_run(run_dir: Path) -> None:
    """Delete what a new run wrote before it failed in its first iteration (config, git revision,
    TensorBoard file, logs): a folder without a checkpoint from a run that cannot start would
    mislead the next command (``eval``, ``--resume`` would repeat the failure). Nothing is
    deleted once a checkpoint exists."""
    import shutil

    if (run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT).exists() or any(
        (run_dir / CHECKPOINT_DIR).glob("model_*.pt")
    ):
        return
    names = (CONFIG_FILE, GIT_FILE, CURRICULUM_LOG, METRICS_LOG, WARMSTART_FILE, EVALS_LOG,
             EVALS_DIR)  # fmt: skip
    for path in [*(run_dir / n for n in names), *run_dir.glob(EVENTS_GLOB)]:
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    for folder in (run_dir / CHECKPOINT_DIR, run_dir / "git"):  # git/: rsl-rl's diff of the code
        shutil.rmtree(folder, ignore_errors=True)


def logged_iterations(run_dir: Path) -> int:
    """The most iterations a run folder's logs say were completed: the last ``completed`` of
    ``metrics.jsonl``, or ``iterations_done`` of ``metrics.json`` (0 when neither says; a damaged
    line or file counts for what it still shows)."""
    done = 0
    with contextlib.suppress(OSError, UnicodeDecodeError):
        for line in (run_dir / METRICS_LOG).read_text().splitlines():
            with contextlib.suppress(ValueError):
                row = json.loads(line)
                if isinstance(row, dict) and isinstance(row.get("completed"), int):
                    done = max(done, row["completed"])
    with contextlib.suppress(OSError, ValueError, UnicodeDecodeError):
        summary = json.loads((run_dir / METRICS_FILE).read_text())
        if isinstance(summary, dict) and isinstance(summary.get("iterations_done"), int):
            done = max(done, summary["iterations_done"])
    return done


class NothingToResumeError(ValueError):
    """A resume that would lose what a run folder holds (its checkpoints are gone, or it asks for
    fewer iterations than are done); the message says what is missing and what to do."""


def require_nothing_to_lose(run_dir: Path) -> None:
    """Refuse to start a run folder without a checkpoint again from iteration 0 when its logs
    show completed iterations: that restart would rewrite them (only a run killed during its
    first iteration, which logged none, starts again)."""
    done = logged_iterations(run_dir)
    if done > 0:
        raise NothingToResumeError(
            f"{run_dir} has {done} completed iteration{'s' * (done != 1)} logged but no "
            f"checkpoint in {run_dir / CHECKPOINT_DIR} ({LAST_CHECKPOINT} or model_<k>.pt): it "
            "cannot be resumed, and starting it again would overwrite its logs; restore "
            f"{CHECKPOINT_DIR}/ from a backup and resume, or start a new run with another "
            "--run-name"
        )


def no_checkpoint_error(run_dir: Path) -> FileNotFoundError:
    """What a command that needs a checkpoint says of a run folder that has none: a run killed
    during its first iteration (it logged none) can be started again with ``--resume``; one
    whose checkpoints were lost after it logged iterations needs them back, or a new run."""
    done = logged_iterations(run_dir)
    where = f"{CHECKPOINT_DIR}/{LAST_CHECKPOINT}"
    if done == 0:
        return FileNotFoundError(
            f"{run_dir} has no checkpoint ({where}): its training stopped during its first "
            f"iteration; continue it with `a2cf-mb train --resume {run_dir}`, or delete the folder"
        )
    return FileNotFoundError(
        f"{run_dir} has no checkpoint ({where} or model_<k>.pt) although it logged {done} "
        f"completed iteration{'s' * (done != 1)}: restore {CHECKPOINT_DIR}/ from a backup, or "
        "start a new run with another --run-name"
    )


def checkpoint_iterations(path: Path) -> int:
    """The iterations completed when checkpoint ``path`` was saved."""
    return int(load_checkpoint(path)["completed_iterations"])


def require_enough_iterations(run_dir: Path, checkpoint: Path, iterations: int) -> None:
    """Refuse a resume to a total of ``iterations`` below what the run has completed (its
    checkpoint's count, or its logs' where they show more): it would relabel the run's rows."""
    done = max(checkpoint_iterations(checkpoint), logged_iterations(run_dir))
    if iterations < done:
        raise NothingToResumeError(
            f"--iterations {iterations} is fewer than the {done} iterations {run_dir} has "
            f"completed: give --iterations {done} or more to continue it (--iterations {done} "
            f"only exports it), or start a new run of {iterations} iterations with another "
            "--run-name"
        )


class RunFolderNotWritableError(OSError):
    """A resume could not write the run folder through (no room, a file-size limit); the
    message says why and what to do."""


WRITE_MARGIN_BYTES = 1 << 20
"""Room a resume needs beyond its checkpoint and logs written once more (TensorBoard's event
file, the JSON files) [bytes]."""


def require_writable(run_dir: Path, checkpoint: Path | None) -> None:
    """Refuse, before a resume writes anything, a run folder it could not write through: a
    folder or log without write permission, a disk without room for a checkpoint written twice
    (the atomic copy) and the logs rewritten, or a file-size limit (``ulimit -f``) below the
    largest file it writes. Otherwise the first write would fail with the folder half
    rewritten."""
    import resource
    import shutil

    for folder in (run_dir, run_dir / CHECKPOINT_DIR):
        if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError(
                errno.EACCES,
                "Permission denied (a resume writes into it; make it writable, e.g. chmod u+w)",
                str(folder),
            )
    logs = [run_dir / n for n in (METRICS_LOG, CURRICULUM_LOG, EVALS_LOG, METRICS_FILE)]
    for path in logs:
        if path.is_file() and not os.access(path, os.W_OK):
            raise PermissionError(
                errno.EACCES,
                "Permission denied (a resume rewrites it; make it writable, e.g. chmod u+w)",
                str(path),
            )
    checkpoint_bytes = checkpoint.stat().st_size if checkpoint is not None else 0
    sizes = [checkpoint_bytes, *(p.stat().st_size for p in logs if p.is_file())]
    needed = checkpoint_bytes + sum(sizes) + WRITE_MARGIN_BYTES
    free = shutil.disk_usage(run_dir).free
    if free < needed:
        raise RunFolderNotWritableError(
            f"{run_dir} is on a disk with {free / 2**20:.1f} MiB free; a resume writes "
            f"{needed / 2**20:.1f} MiB before its first iteration ends (the checkpoint twice and "
            "its logs): free some space and resume again; the run folder is unchanged",
        )
    limit, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    largest = max(sizes) + WRITE_MARGIN_BYTES
    if limit != resource.RLIM_INFINITY and limit < largest:
        raise RunFolderNotWritableError(
            f"the file-size limit of this shell (ulimit -f: {limit // 1024} KiB) is below the "
            f"{largest // 1024} KiB a resume of {run_dir} writes in one file: raise it (ulimit -f "
            "unlimited) and resume again; the run folder is unchanged",
        )


def check_resume(
    run_dir: Path, iterations: int, writable: bool = True, quiet: bool = False
) -> Path | None:
    """Everything a resume of ``run_dir`` to ``iterations`` in all needs, checked before the
    folder changes (a refused resume leaves every byte as it was): a checkpoint, or no logged
    iteration to lose; a total no smaller than what is done; with ``writable``, room and
    permission to write. Returns the checkpoint it continues from (None: from iteration 0);
    ``quiet``: no warning about a fallback checkpoint (a check ahead of the resume itself)."""
    checkpoint = resumable_checkpoint(run_dir, quiet=quiet)
    if checkpoint is None:
        require_nothing_to_lose(run_dir)
    else:
        require_enough_iterations(run_dir, checkpoint, iterations)
    if writable:
        require_writable(run_dir, checkpoint)
    return checkpoint


@dataclass(frozen=True)
class StartPoint:
    """Where a run starts (:func:`start_point`)."""

    cfg: TrainConfig  # the run's config (for a resume: the saved one with the new iterations)
    checkpoint: Path | None  # the checkpoint to continue from; None: from iteration 0
    saved_eta0: list | None  # (P, 6) eta0 of config.json when a resume restarts from iteration 0


def start_point(cfg: TrainConfig, run_dir: Path) -> StartPoint:
    """The config and checkpoint a run starts from. A new run needs an unused folder; a resume
    takes the saved config (with ``cfg.iterations``, the new total) and the newest readable
    checkpoint, or, killed before its first checkpoint, starts over from iteration 0 (the same
    seed gives the same run; the lost iterations' logs go). In a torchrun job rank 0 alone checks
    and cleans the folder: the others may come after it has started writing."""
    main = _torchrun_rank() == 0
    if not cfg.resume:
        if main:
            require_unused(run_dir)
        return StartPoint(cfg, None, None)
    saved = load_run_config(run_dir)
    cfg = replace(saved, iterations=cfg.iterations, resume=cfg.resume)
    checkpoint = check_resume(run_dir, cfg.iterations, writable=main)
    if main:
        # what writers killed mid-write left (a SIGKILL during a save): never read
        for folder in (run_dir, run_dir / CHECKPOINT_DIR, run_dir / EVALS_DIR):
            remove_stale_temp_files(folder)
    if checkpoint is not None:
        return StartPoint(cfg, checkpoint, None)
    if main:
        print(
            f"a2cf-mb train: warning: {run_dir} has no checkpoint yet (stopped during its first "
            "iteration); starting it again from iteration 0 with its saved config",
            file=sys.stderr,
        )
        for stale in [*run_dir.glob(EVENTS_GLOB), run_dir / CURRICULUM_LOG, run_dir / METRICS_LOG]:
            stale.unlink(missing_ok=True)
    return StartPoint(cfg, None, json.loads((run_dir / CONFIG_FILE).read_text()).get("eta0"))
