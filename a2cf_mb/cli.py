"""The ``a2cf-mb`` command line. Thin: each subcommand parses a config and calls one library function.

Subcommands live in ``a2cf_mb/commands/<name>.py``; each module defines ``register(subparsers)``
which adds its parser and sets ``func`` to a callable taking the parsed namespace.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import pickle
import re
import sys
import time
import traceback
import warnings
import zipfile
from pathlib import Path

COMMAND_MODULES: tuple[str, ...] = (
    "a2cf_mb.commands.info",
    "a2cf_mb.commands.bench",
    "a2cf_mb.commands.train",
    "a2cf_mb.commands.eval",
    "a2cf_mb.commands.eval_curve",
    "a2cf_mb.commands.compare",
    "a2cf_mb.commands.list_tasks",
    "a2cf_mb.commands.demo",
    "a2cf_mb.commands.play",
    "a2cf_mb.commands.solve_walk",
    "a2cf_mb.commands.solve_dance",
    "a2cf_mb.commands.solve_backflip",
    "a2cf_mb.commands.coach",
)


class UsageError(ValueError):
    """A command line argparse refused (unknown flag, bad value, NaN in a float flag)."""


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a refused command line raises :class:`UsageError` (reported by :func:`main`
    in one line, like every other user error) instead of printing the usage block and exiting."""

    def error(self, message: str):  # type: ignore[override]
        raise UsageError(f"{message} (see `{self.prog} --help`)")


def command_name(module_name: str) -> str:
    """The subcommand a module of :data:`COMMAND_MODULES` registers (``solve_walk`` ->
    ``solve-walk``)."""
    return module_name.rsplit(".", 1)[1].replace("_", "-")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered, or only ``command``'s when it names
    one (a command line that names its command does not import the others' libraries: torch,
    rsl-rl and MuJoCo cost seconds for ``solve-backflip``)."""
    parser = OneLineParser(
        prog="a2cf-mb",
        description="A2CF with a model-based wrench oracle for the Unitree G1.",
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        help=f"show the full traceback of any error (as {DEBUG_ENV}=1); before COMMAND",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    names = {command_name(m): m for m in COMMAND_MODULES}
    if command in names:
        importlib.import_module(names[command]).register(subparsers)
        return parser
    for module_name in COMMAND_MODULES:
        try:
            importlib.import_module(module_name).register(subparsers)
        except ModuleNotFoundError as err:
            if missing_oracle_library(err) is None:
                raise
            # A training-only install: the help still lists the oracle's commands, and running
            # one reports the missing library (main's one line).
            _register_unavailable(subparsers, command_name(module_name), err)
    return parser


ORACLE_LIBRARIES: dict[str, str] = {
    "pinocchio": "pin",
    "placo": "placo",
    "casadi": "casadi",
    "proxsuite": "proxsuite",
}
"""The model-based oracle's solver libraries, import name -> pip package. Training (stand, walk,
backflip) runs without them; the oracle's commands, ``info`` and the dance task need them."""


def missing_oracle_library(exc: BaseException) -> str | None:
    """The pip package of the oracle library whose import failed in ``exc``, else None."""
    if isinstance(exc, ModuleNotFoundError) and exc.name:
        return ORACLE_LIBRARIES.get(exc.name.split(".")[0])
    return None


def _oracle_requirements() -> list[str]:
    """The oracle libraries as a2cf-mb requires them (``pin==3.8.0``, ...), from its metadata."""
    from importlib import metadata

    try:
        required = metadata.requires("a2cf-mb") or []
    except metadata.PackageNotFoundError:
        required = []
    pins = {re.split(r"[<>=!~ ;\[]", r, maxsplit=1)[0]: r.split(";")[0].strip() for r in required}
    return [pins.get(package, package) for package in ORACLE_LIBRARIES.values()]


def oracle_library_message(exc: ModuleNotFoundError) -> str:
    """The line printed when an oracle library is missing: which, and the command to install."""
    packages = " ".join(f"'{r}'" for r in _oracle_requirements())
    return (
        f"this needs the model-based oracle's solver libraries, and '{exc.name}' is not installed "
        f"(pip package '{missing_oracle_library(exc)}'): pip install {packages} (a training-only "
        "install leaves them out, see docs/gpu.md)"
    )


def _register_unavailable(
    subparsers: argparse._SubParsersAction, name: str, err: ModuleNotFoundError
) -> None:
    """A placeholder for a command whose libraries are missing: listed, and failing when run."""
    parser = subparsers.add_parser(
        name, help=f"(not available: needs the oracle's libraries, {err.name} is not installed)"
    )

    def unavailable(args: argparse.Namespace) -> int:
        raise err

    parser.set_defaults(func=unavailable)


DEBUG_ENV = "A2CF_DEBUG"
"""Set this environment variable to 1 (or give ``a2cf-mb --debug``) to get full tracebacks."""

TRACEBACK_DIR_ENV = "A2CF_TRACEBACK_DIR"
"""Folder where the traceback of an unexpected error is saved; unset: ``$XDG_STATE_HOME/a2cf-mb``
(``~/.local/state/a2cf-mb``)."""

USER_ERRORS: tuple[type[BaseException], ...] = (
    ValueError,  # bad values, malformed files (library errors speak to the user; JSON, Unicode)
    OSError,  # missing, unreadable or unwritable paths (FileNotFound, Permission, IsADirectory...)
    zipfile.BadZipFile,  # a junk or truncated .npz / .pt read without a guard
    EOFError,  # a truncated file
    pickle.UnpicklingError,  # a truncated or foreign pickle (checkpoints)
)
"""Exceptions a user can cause with an input: printed as one line, exit code 2. Anything else is
a bug and keeps its traceback (exit code 1)."""

USER_ERROR_NAMES: tuple[str, ...] = (
    "InfeasibleBackflipError",
    "BackflipAuditError",
    "RunFolderBusyError",
    "MissingExtraError",
    "RenderUnavailableError",
    "ViewerUnavailableError",
)
"""Outcomes of a valid run that the user resolves by changing the problem, installing an extra
(``MissingExtraError``: the message says which), running where a GL context or a display exists
(``RenderUnavailableError``, ``ViewerUnavailableError``), or by waiting for the process that
writes the same run folder (matched by class name so this module does not import the solvers or
the trainer)."""


FULL_DISK_ERRNOS: tuple[int, ...] = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
"""OS errors of a disk or quota that is full, or a file over the shell's size limit."""


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` is an input or outcome error to report in one line (see USER_ERRORS), or
    an oracle library missing from a training-only install."""
    return (
        isinstance(exc, USER_ERRORS)
        or type(exc).__name__ in USER_ERROR_NAMES
        or missing_oracle_library(exc) is not None
    )


def user_message(exc: BaseException) -> str:
    """The line printed for a user error: the library's message, or for a bare OS error the
    path, the reason and what to check; for a missing oracle library what to install."""
    if isinstance(exc, ModuleNotFoundError) and missing_oracle_library(exc) is not None:
        return oracle_library_message(exc)
    if isinstance(exc, OSError) and exc.errno in FULL_DISK_ERRNOS:
        where = f" writing '{exc.filename}'" if exc.filename is not None else ""
        return (
            f"{exc.strerror or exc}{where}: the disk is full or a file reached the file-size "
            "limit (ulimit -f); free space or raise the limit, then run the command again (files "
            "are written whole, so a run resumes from its last checkpoint)"
        )
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return (
            f"{exc.strerror}: '{exc.filename}' ({type(exc).__name__}); check the path, that it is "
            "of the expected kind (file or folder) and its permissions."
        )
    if isinstance(exc, zipfile.BadZipFile | EOFError | pickle.UnpicklingError):
        return (
            f"a file could not be read ({type(exc).__name__}: {exc}); it is truncated or not of "
            "the expected format: regenerate it."
        )
    return str(exc) or type(exc).__name__


def save_traceback(exc: BaseException, command: str) -> Path | None:
    """Write the full traceback of ``exc`` (raised by ``command``) to a new file of the traceback
    folder (:data:`TRACEBACK_DIR_ENV`); its path, or None when it cannot be written."""
    state = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    folder = Path(os.environ.get(TRACEBACK_DIR_ENV) or Path(state) / "a2cf-mb")
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    path = folder / f"traceback-{stamp}-{os.getpid()}.txt"
    text = "".join(traceback.format_exception(exc))
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{command} (argv: {sys.argv})\n{text}")
    except OSError:
        return None
    return path


def unexpected_error_line(exc: BaseException, command: str, saved: Path | None) -> str:
    """The one line printed for an exception that is not a user error (a bug, or a fault this
    toolkit does not know yet): the command, the exception, where its traceback went."""
    lines = str(exc).strip().splitlines()
    what = f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__
    where = (
        f"the full traceback is in {saved}"
        if saved is not None
        else f"the traceback could not be saved; rerun with {DEBUG_ENV}=1 to see it"
    )
    return (
        f"{command}: unexpected error: {what} ({where}; please report it with that file; "
        f"`a2cf-mb --debug ...` or {DEBUG_ENV}=1 shows it here)"
    )


class EnvironmentSettingError(ValueError):
    """An environment variable the toolkit's libraries read holds what they cannot use."""


GL_SETTINGS: tuple[str, ...] = (
    "", "egl", "glfw", "osmesa", "glx", "enable", "enabled", "on", "true", "1",
    "disable", "disabled", "off", "false", "0",
)  # fmt: skip
"""The values of ``MUJOCO_GL`` MuJoCo accepts on Linux (its ``gl_context``)."""


def check_gl_setting() -> None:
    """Refuse, before a command imports MuJoCo, a ``MUJOCO_GL`` that MuJoCo cannot load: one
    that names no backend, or a backend whose library is missing (``osmesa`` without OSMesa
    fails inside MuJoCo's import). Only when the variable is set: MuJoCo is then imported here."""
    wanted = os.environ.get("MUJOCO_GL")
    if wanted is None or "mujoco" in sys.modules:
        return
    if wanted.lower().strip() not in GL_SETTINGS:
        raise EnvironmentSettingError(
            f"MUJOCO_GL={wanted} names no GL backend MuJoCo knows: set MUJOCO_GL=egl (offscreen, "
            "for videos), glfw (with a display) or osmesa, or unset it (training and "
            "evaluations without a video need none)"
        )
    try:
        import mujoco  # noqa: F401
    except Exception as err:  # mujoco's import of the backend raises what the GL library does
        reason = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise EnvironmentSettingError(
            f"MUJOCO_GL={wanted}: MuJoCo cannot load this GL backend ({type(err).__name__}: "
            f"{reason}); unset MUJOCO_GL, or set MUJOCO_GL=egl (needs libegl1), or install the "
            "backend's library (osmesa: libosmesa6)"
        ) from err


def _format_warning(message, category, filename, lineno, line=None) -> str:
    return f"a2cf-mb: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code.

    User errors (:data:`USER_ERRORS`: a bad flag value, a malformed clip, a missing or unwritable
    path, a truncated file) print one line on stderr naming the input and what to do, exit code 2.
    Any other exception is a bug (or a fault not known yet): one line with the command, the
    exception and the file its traceback was saved to (:func:`save_traceback`), exit code 1.
    ``a2cf-mb --debug COMMAND ...`` or ``A2CF_DEBUG=1`` re-raises both with the traceback.
    """
    warnings.formatwarning = _format_warning
    command = "a2cf-mb"
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = os.environ.get(DEBUG_ENV) == "1"
    if argv[:1] == ["--debug"]:
        debug, argv = True, argv[1:]
    if argv and argv[0] in {command_name(m) for m in COMMAND_MODULES}:
        command = f"a2cf-mb {argv[0]}"  # named in a refusal that comes before parsing
    try:
        check_gl_setting()
        args = build_parser(argv[0] if argv else None).parse_args(argv)
        command = f"a2cf-mb {args.command}"
        result = args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if debug:
            raise
        if not is_user_error(exc):
            print(
                unexpected_error_line(exc, command, save_traceback(exc, command)), file=sys.stderr
            )
            return 1
        print(
            f"{command}: error: {user_message(exc)} (set {DEBUG_ENV}=1 for the full traceback)",
            file=sys.stderr,
        )
        return 2
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
