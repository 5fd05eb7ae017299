"""An output folder: one run at a time (a lock), and files written whole or not at all.

The lock is an advisory ``flock`` on ``DIR/.lock``, held for as long as ``eval`` or
``report`` writes into the folder. The kernel releases it when its process ends, however
it ends (kill -9 included), so a stale lock never blocks a resume; the file keeps the
holder's pid, host, command and start time for the message a second process prints.
``flock`` is local to one machine: on a network file system shared by several hosts, do
not point two hosts at one folder.

Every output file is first written to a temporary file in its folder and then renamed
over its name (``os.replace``): a reader never sees half a file, a crash leaves the
previous version, and a symbolic link planted under an output's name is replaced, never
followed.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import sqlite3
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from harness.errors import InputError

LOCK_NAME = ".lock"
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def output_folder(path: Path, option: str = "--out", what: str = "the results folder") -> Path:
    """Create the folder (and its parents) for results; one line on failure."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(option, None, f"{path} exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise storage_error(exc, path, f"cannot create {what}") from None
    return path


def storage_error(exc: BaseException, path: Path | str, doing: str) -> InputError:
    """An OSError or SQLite error met while reading or writing ``path``, as one line."""
    if isinstance(exc, OSError):
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        where = exc.filename if exc.filename else path
    else:
        reason, where = str(exc), path
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC or "disk is full" in reason:
        reason += " (nothing recorded so far is lost: free some space and run the same command again)"
    return InputError(str(where), None, f"{doing}: {reason}")


@contextmanager
def storage(path: Path | str, doing: str) -> Iterator[None]:
    """Turn OSError and SQLite errors inside the block into one line about ``path``."""
    try:
        yield
    except InputError:
        raise
    except (OSError, sqlite3.Error) as exc:
        raise storage_error(exc, path, doing) from None


@contextmanager
def folder_lock(folder: Path, command: str) -> Iterator[None]:
    """Hold ``folder``'s lock for the block; InputError naming the holder if another
    process holds it."""
    path = Path(folder) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError(str(path), None, "is a symbolic link; remove it (the lock file is the folder's own)")
        raise storage_error(exc, path, "cannot create the folder's lock") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(str(folder), None, f"in use by {_holder(fd)}; wait for it to finish, or give "
                                                "another --out") from None
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
                  "since": datetime.now(UTC).isoformat(timespec="seconds")}
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(holder) + "\n").encode(), 0)
        except OSError:
            pass  # the lock holds without its note (a full disk, say); the message is then vaguer
        yield
    finally:
        os.close(fd)  # releases the lock


def _holder(fd: int) -> str:
    try:
        note = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
        return f"{note['command']} (pid {note['pid']} on {note['host']}, since {note['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another gpis-harness process"


def write_atomic(path: Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(temporary path)`` and rename the result to ``path``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # as an ordinary new file (mkstemp makes it private)
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def write_text(path: Path, text: str) -> Path:
    return write_atomic(path, lambda tmp: tmp.write_text(text))


def command_line() -> str:
    """This process's command, for the lock's note."""
    return " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])[:300]
