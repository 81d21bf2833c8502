"""Files the project writes and reads: atomic writes, atomic folders, guarded reads, revisions.

Every file is written to a temporary name beside its target, flushed, ``fsync``-ed and renamed into
place (:func:`atomic_write_bytes` and the text / JSON / npz variants), so a reader sees the old
file or the new one, never a truncated one. A folder of files (an oracle artifact) is built beside
its target (``.<name>.tmp-<pid>``) and swapped into place by :func:`atomic_folder`: on Linux with
one ``renameat2(RENAME_EXCHANGE)``, elsewhere by renaming the old folder away, the new one in and
deleting the old one (an interruption between the two renames is repaired by
:func:`recover_folder`, which puts the old folder back). Leftovers of killed writers (temporary
folders of processes that no longer run) are removed by the next writer of the same target.

:func:`read_npz` turns a junk, truncated or pickled ``.npz`` into a :class:`ValueError` that names
the file and what it was for; :func:`check_writable_dir` and :func:`check_output_folder` fail
before a long computation rather than after it.

Fault tests set :data:`SAVE_DELAY_ENV` to sleep after each file written and before the folder swap,
so a SIGKILL lands inside the saving window deterministically.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import json
import os
import shutil
import subprocess
import tempfile
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

SAVE_DELAY_ENV = "A2CF_TEST_SAVE_DELAY_S"
"""Test hook: seconds to sleep after each atomic file write and before a folder swap."""

_TMP_TAG = ".tmp-"
_OLD_TAG = ".old-"
_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100


class OutputExistsError(ValueError):
    """An output folder exists and replacing it was not asked for."""


def _test_delay() -> None:
    delay = os.environ.get(SAVE_DELAY_ENV)
    if delay:
        time.sleep(float(delay))


def _fsync_dir(path: Path) -> None:
    """Make a rename inside ``path`` durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a directory; the rename itself is atomic
    finally:
        os.close(fd)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file, flush, fsync, rename); returns the path."""
    path = Path(path)
    tmp = path.parent / f".{path.name}{_TMP_TAG}{os.getpid()}"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as err:
        with contextlib.suppress(OSError):  # e.g. the folder is a file: there is no temp file
            tmp.unlink(missing_ok=True)
        if err.filename != str(tmp) or not err.strerror:
            raise
        # The temp name means nothing to the user: name the file they asked for.
        raise type(err)(err.errno, f"{err.strerror} (writing it)", str(path)) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)
    _test_delay()
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; returns the path."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | Path, obj: Any, indent: int = 2) -> Path:
    """Write ``obj`` as JSON to ``path`` atomically; returns the path."""
    return atomic_write_text(path, json.dumps(obj, indent=indent) + "\n")


def atomic_save_npz(
    path: str | Path, arrays: dict[str, np.ndarray], compressed: bool = True
) -> Path:
    """Write ``arrays`` as an ``.npz`` to ``path`` atomically (no ``.npz`` is appended)."""
    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buffer, **arrays)
    return atomic_write_bytes(path, buffer.getvalue())


def atomic_savefig(fig: Any, path: str | Path, **kwargs: Any) -> Path:
    """Save a matplotlib figure to ``path`` atomically (format from the suffix; ``kwargs`` go to
    ``savefig``, e.g. ``dpi``)."""
    path = Path(path)
    buffer = io.BytesIO()
    fig.savefig(buffer, format=path.suffix.lstrip(".") or "png", **kwargs)
    return atomic_write_bytes(path, buffer.getvalue())


def read_npz(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """All arrays of the ``.npz`` at ``path``, loaded eagerly (so a truncated member fails here).

    ``what`` says what the file is for (e.g. ``"--warm-start solution"``); a missing, junk,
    truncated or pickled file raises a :class:`ValueError` naming the file and ``what``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} '{path}' does not exist (or is not a file).")
    if not zipfile.is_zipfile(path):
        raise ValueError(
            f"{what} '{path}' is not an .npz archive (no zip directory: junk, truncated or another "
            "format). Regenerate it or pass another file."
        )
    try:
        with np.load(path, allow_pickle=False) as npz:
            if not isinstance(npz, np.lib.npyio.NpzFile):
                raise ValueError("it holds a single array, not an .npz archive")
            return {key: np.asarray(npz[key]) for key in npz.files}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as err:
        raise ValueError(
            f"{what} '{path}' is not a readable .npz archive ({type(err).__name__}: {err}); "
            "it is truncated or not written by numpy.savez. Regenerate it or pass another file."
        ) from err


def git_revision(path: Path) -> dict[str, Any]:
    """Git commit and dirty flag of the repository holding ``path`` (None outside git).

    Returns ``{"commit": str | None, "dirty": bool | None}``.
    """

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(
                ["git", *args], cwd=path, capture_output=True, text=True, timeout=10, check=True
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip()

    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain") if commit is not None else None
    return {"commit": commit, "dirty": bool(status) if status is not None else None}


def git_refusal(path: Path) -> str | None:
    """Why git gives no commit for the checkout holding ``path`` although it is one (git's first
    line, e.g. its "dubious ownership" of a checkout owned by another user); None when git
    reads it, or ``path`` is in no git checkout (an installed package) or git is missing."""
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=path, capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.SubprocessError):
        return None
    said = done.stderr.strip().splitlines()
    if done.returncode == 0 or not said or "not a git repository" in said[0]:
        return None
    return said[0].removeprefix("fatal: ")


def check_writable_dir(path: str | Path, what: str) -> Path:
    """Make sure files can be created in folder ``path`` (created if missing); returns it.

    Call before long work so a read-only or misspelt output fails in a second, not after the
    computation. Raises :class:`ValueError` naming ``what`` and ``path``.
    """
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise ValueError(f"{what} '{path}' is a file, not a folder; choose another path.")
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".a2cf-write-probe-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise ValueError(
            f"{what} '{path}' is not writable ({err.strerror or err}); choose a writable folder "
            "or fix its permissions."
        ) from err
    return path


def check_output_folder(folder: str | Path, overwrite: bool, what: str = "--out") -> Path:
    """Check before any work that ``folder`` can be written: its parent is writable, and it does
    not exist unless ``overwrite``. Raises :class:`OutputExistsError` / :class:`ValueError`."""
    folder = Path(folder).expanduser()
    recover_folder(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{what} '{folder}' is a file, not a folder; choose another path.")
    if folder.exists() and not overwrite and any(folder.iterdir()):
        raise OutputExistsError(
            f"{what} '{folder}' already exists; pass --overwrite to replace it (the old folder is "
            "replaced as a whole, atomically) or choose another --out."
        )
    check_writable_dir(folder.parent, f"{what} parent folder")
    return folder


def _pid_of(name: str, tag: str) -> int | None:
    try:
        return int(name.rsplit(tag, 1)[1])
    except (IndexError, ValueError):
        return None


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (a zombie, killed but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # it exists, owned by another user
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True  # no /proc (macOS) or it just ended: os.kill said it exists
    return stat[stat.rindex(")") + 2 :].split()[0] != "Z"


def _leftovers(target: Path, tag: str) -> list[tuple[Path, int]]:
    prefix = f".{target.name}{tag}"
    if not target.parent.is_dir():
        return []
    out = []
    for entry in target.parent.iterdir():
        if entry.name.startswith(prefix):
            pid = _pid_of(entry.name, tag)
            if pid is not None and not process_alive(pid):
                out.append((entry, pid))
    return out


def remove_stale_temp_files(folder: str | Path) -> list[Path]:
    """Delete the temporary files (``.<name>.tmp-<pid>``) that writers killed during
    :func:`atomic_write_bytes` left in ``folder``: those whose process no longer runs. Returns
    the removed paths (a live writer's file is kept)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    removed = []
    for entry in folder.iterdir():
        if not entry.name.startswith(".") or _TMP_TAG not in entry.name or not entry.is_file():
            continue
        pid = _pid_of(entry.name, _TMP_TAG)
        if pid is not None and not process_alive(pid):
            entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed


def recover_folder(target: str | Path) -> None:
    """Repair what a killed :func:`atomic_folder` left beside ``target``.

    A missing ``target`` with a ``.<name>.old-<pid>`` of a dead process beside it was interrupted
    between its two renames: the old, complete folder is put back. Temporary folders of dead
    writers are deleted.
    """
    target = Path(target)
    olds = _leftovers(target, _OLD_TAG)
    if not target.exists() and olds:
        os.rename(olds[0][0], target)
        _fsync_dir(target.parent)
        olds = olds[1:]
    for entry, _ in olds + _leftovers(target, _TMP_TAG):
        shutil.rmtree(entry, ignore_errors=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two existing paths atomically (Linux ``renameat2``); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [
        ctypes.c_int,
        ctypes.c_char_p,
        ctypes.c_int,
        ctypes.c_char_p,
        ctypes.c_uint,
    ]
    if renameat2(_AT_FDCWD, bytes(a), _AT_FDCWD, bytes(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: file system or kernel lacks it
        return False
    raise OSError(err, os.strerror(err), str(a))


def _fsync_tree(root: Path) -> None:
    for dirpath, _, filenames in os.walk(root):
        for name in filenames:
            with open(os.path.join(dirpath, name), "rb") as f:
                os.fsync(f.fileno())
        _fsync_dir(Path(dirpath))


@contextlib.contextmanager
def atomic_folder(target: str | Path, overwrite: bool) -> Iterator[Path]:
    """Build a folder beside ``target`` and put it in place as a whole when the block ends.

    Yields the temporary folder to write into. On success every file is fsync-ed and the folder
    replaces ``target`` (an existing ``target`` only when ``overwrite``; it is swapped out, never
    mixed with the new files, then deleted). On an exception the temporary folder is removed and
    ``target`` is left as it was.
    """
    target = Path(target).expanduser().absolute()
    recover_folder(target)
    if target.exists() and not overwrite and (not target.is_dir() or any(target.iterdir())):
        raise OutputExistsError(
            f"'{target}' already exists; pass --overwrite to replace it or choose another --out."
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.parent / f".{target.name}{_TMP_TAG}{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        yield tmp
        _fsync_tree(tmp)
        _fsync_dir(target.parent)
        _test_delay()
        if target.exists():
            if _exchange(tmp, target):
                _fsync_dir(target.parent)
                shutil.rmtree(tmp)  # now holds the old folder
                return
            old = target.parent / f".{target.name}{_OLD_TAG}{os.getpid()}"
            os.rename(target, old)
            os.rename(tmp, target)
            _fsync_dir(target.parent)
            shutil.rmtree(old)
        else:
            os.rename(tmp, target)
            _fsync_dir(target.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
