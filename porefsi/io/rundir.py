"""Output directories of porefsi's commands: checked before use, one run at a time, clear errors.

* :func:`check_output_dir` validates a directory a command will write to *without* creating or
  changing anything (a file in the way, a path under a file, a folder that cannot be written);
* :func:`lock` holds an exclusive ``fcntl.flock`` on ``DIR/.porefsi.lock`` (which names the pid,
  host and command of the holder) for the life of a run: a second run into the same directory
  fails at once with :class:`RunLockedError` naming the holder; the kernel drops the lock when
  the holder dies, so a killed run never blocks the next one;
* :func:`output_errors` turns an ``OSError`` met while writing (full disk, read-only
  filesystem, permission) into a one-line :class:`~porefsi.errors.InputError` with the path,
  the cause and the fix.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import socket
import sys
import time
from pathlib import Path

from porefsi.errors import InputError

__all__ = ["LOCK_NAME", "RunLockedError", "check_output_dir", "lock", "output_errors", "describe_os_error"]

#: Lock file inside a run directory (removed when the run ends; a stale one is harmless).
LOCK_NAME = ".porefsi.lock"


class RunLockedError(InputError):
    """Another porefsi process is writing into the same output directory."""


def check_output_dir(path: str | Path, option: str = "-o DIR") -> Path:
    """Check that ``path`` can be a run directory, changing nothing; return it as a Path.

    Raises
    ------
    InputError
        ``path`` is a file, lies under a file, or its nearest existing folder cannot be written.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"output {p} exists and is not a folder; pass another {option}")
    probe = p
    while not probe.exists():  # the nearest existing ancestor is where the folders get created
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise InputError(f"cannot create output folder {p}: {probe} is a file, not a folder; pass another {option}")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"cannot write to {probe} (permission denied or read-only); pass another {option}")
    return p


@contextlib.contextmanager
def lock(directory: str | Path, command: str | None = None):
    """Hold the exclusive lock of run directory ``directory`` (created if missing) for the block.

    Raises
    ------
    RunLockedError
        Another live process holds it; the message names its pid, host and command.
    InputError
        The directory or the lock file cannot be created (see :func:`output_errors`).
    """
    d = Path(directory)
    path = d / LOCK_NAME
    with output_errors(d):
        d.mkdir(parents=True, exist_ok=True)
        fd = _acquire(path)
    try:
        text = f"pid {os.getpid()} on {socket.gethostname()}, started {time.strftime('%Y-%m-%d %H:%M:%S')}"
        cmd = command if command is not None else " ".join(["porefsi", *sys.argv[1:]])
        with contextlib.suppress(OSError):  # the lock is what counts; the note only helps the message
            os.ftruncate(fd, 0)
            os.write(fd, f"{text}: {cmd}\n".encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)  # while still holding it: a waiting process sees the file is gone
        os.close(fd)


def _acquire(path: Path) -> int:
    """Open and flock ``path`` (non-blocking), retrying if the holder removed it meanwhile."""
    for _ in range(100):
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_note(fd)
            os.close(fd)
            raise RunLockedError(
                f"output folder {path.parent} is in use by another porefsi run ({holder}); wait for it to "
                "finish, or pass another -o DIR") from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)  # we locked a file its holder had just removed: try the new one
    raise RunLockedError(f"could not lock output folder {path.parent}: it keeps changing; pass another -o DIR")


def _read_note(fd: int) -> str:
    try:
        note = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip()
    except OSError:
        note = ""
    return note or "holder unknown"


def describe_os_error(exc: OSError, path: str | Path | None = None) -> str:
    """One line for an ``OSError`` met while writing: what, where, and what to do."""
    where = exc.filename or path or "an output file"
    code = exc.errno
    if code == errno.ENOSPC or code == errno.EDQUOT:
        return (f"no space left on the device while writing {where}: free some space (or pass another -o DIR on "
                "a larger disk); the last checkpoint, if any, was kept: continue with --resume")
    if code in (errno.EROFS, errno.EACCES, errno.EPERM):
        return f"cannot write {where}: {exc.strerror or exc} (read-only or not permitted); pass another -o DIR"
    if code in (errno.ENOTDIR, errno.EEXIST, errno.EISDIR):
        return f"cannot write {where}: {exc.strerror or exc} (a file is in the way of a folder); pass another -o DIR"
    return f"cannot write {where}: {exc.strerror or exc}; check the output folder and pass another -o DIR if needed"


@contextlib.contextmanager
def output_errors(path: str | Path | None = None):
    """Turn an ``OSError`` raised in the block into :class:`InputError` (see :func:`describe_os_error`)."""
    try:
        yield
    except OSError as exc:
        raise InputError(describe_os_error(exc, path)) from exc
