"""A call in a process of its own: a fork of the caller that runs one function and sends
back its JSON result. Whatever the function writes stays in its copy of the caller's
memory; its crash, exit or kill ends only that process; its deadline is kept from
outside (the process is killed); its memory is capped. Every plan runs this way.

Linux and other POSIX systems (os.fork); the harness's local pool needs them too.
"""

from __future__ import annotations

import json
import os
import resource
import select
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass

from harness.errors import describe

#: How a call ended: its function returned (``value`` holds the result), raised an
#: Exception (``message``), crashed (raised a BaseException such as SystemExit or
#: KeyboardInterrupt, ran out of memory, exited or was killed), or ran past its deadline
#: and was killed.
KINDS = ("returned", "raised", "crashed", "overtime")


@dataclass(frozen=True)
class Outcome:
    """What became of an isolated call: its kind (KINDS), the function's result, a one-line
    message, the traceback when it raised, and ``seconds`` from the fork to its end."""

    kind: str
    value: object
    message: str
    seconds: float
    traceback: str = ""


def call(fn, *args, deadline_s: float | None = None, memory_bytes: int | None = None) -> Outcome:
    """``fn(*args)`` in a forked process. Its result must be JSON-ready. ``deadline_s``:
    the process is killed (SIGKILL) that many seconds after the fork, whatever it is
    doing. ``memory_bytes``: its address space may grow by that much beyond the caller's
    (RLIMIT_AS; an allocation past it raises MemoryError there, a crash).

    The process ignores SIGINT: Ctrl-C belongs to the caller, which kills the process and
    raises KeyboardInterrupt as usual. It also ends when the caller dies."""
    read_fd, write_fd = os.pipe()
    caller = os.getpid()
    for stream in (sys.stdout, sys.stderr):  # or the child would write the caller's buffers again
        _flush(stream)
    start = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the child, which never returns
        os.close(read_fd)
        _run_child(fn, args, write_fd, caller, memory_bytes)
    os.close(write_fd)
    status = None
    try:
        data, timed_out, status = _collect(read_fd, pid, None if deadline_s is None else start + deadline_s)
        if timed_out:
            os.kill(pid, signal.SIGKILL)
        if status is None:
            _, status = os.waitpid(pid, 0)
    finally:
        os.close(read_fd)
        if status is None:  # interrupted (Ctrl-C) or failed while waiting: leave nothing behind
            _kill_and_reap(pid)
    seconds = time.perf_counter() - start
    if timed_out:
        return Outcome("overtime", None, f"killed after {seconds:.1f} s (deadline {deadline_s:g} s)", seconds)
    try:
        kind, value, message, trace = json.loads(data)
    except ValueError:  # nothing, or part of a result: the process died before it finished writing
        return Outcome("crashed", None, _ending(status), seconds)
    return Outcome(kind, value, message, seconds, trace)


def die_with(pid: int) -> None:
    """End this process (exit code 1) as soon as process ``pid`` ends, from a daemon
    thread: a pidfd where Linux has one (at once), else a poll every 0.2 s. For processes
    whose life only makes sense while ``pid`` lives (the pool's workers, an isolated
    call)."""
    try:
        handle = os.pidfd_open(pid)
    except (AttributeError, OSError):
        handle = None
    if not _alive(pid):
        os._exit(1)

    def watch():
        if handle is not None:
            select.select([handle], [], [])  # readable once the process has ended
        else:
            while _alive(pid):
                time.sleep(0.2)
        os._exit(1)

    threading.Thread(target=watch, name="die-with", daemon=True).start()


def _run_child(fn, args, write_fd: int, caller: int, memory_bytes: int | None) -> None:  # pragma: no cover
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        die_with(caller)
        if memory_bytes is not None:
            _limit_address_space(memory_bytes)
        try:
            payload = ["returned", fn(*args), "", ""]
        except MemoryError as exc:
            payload = ["crashed", None, f"ran out of memory ({_limit_text(memory_bytes)}): {describe(exc)}",
                       traceback.format_exc()]
        except Exception as exc:  # noqa: BLE001 - the function's fault, reported to the caller
            payload = ["raised", None, describe(exc), traceback.format_exc()]
        except BaseException as exc:  # noqa: BLE001 - SystemExit, KeyboardInterrupt, GeneratorExit, ...
            payload = ["crashed", None, f"raised {describe(exc)}", traceback.format_exc()]
        try:
            data = json.dumps(payload).encode()
        except (TypeError, ValueError) as exc:
            data = json.dumps(["raised", None, f"its result is not JSON-ready: {describe(exc)}", ""]).encode()
        view = memoryview(data)
        while view:
            view = view[os.write(write_fd, view):]
    except BaseException:  # noqa: BLE001 - never let the child return into the caller's code
        traceback.print_exc()  # the harness's own fault here: the process ends without a result
        code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            _flush(stream)
        os._exit(code)


def _collect(fd: int, pid: int, deadline: float | None) -> tuple[bytes, bool, int | None]:
    """What process ``pid`` writes to ``fd``, until the pipe ends or the process does (a
    process it started may hold the pipe open after it), or the deadline passes: (the
    bytes, whether the deadline passed, the exit status if the process was reaped)."""
    chunks = []
    while True:
        wait = 0.2 if deadline is None else min(0.2, deadline - time.perf_counter())
        if wait <= 0:
            return b"".join(chunks), True, None
        if select.select([fd], [], [], wait)[0]:
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                return b"".join(chunks), False, None
            chunks.append(chunk)
            continue
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:  # it wrote everything before it ended: take what the pipe still holds
            os.set_blocking(fd, False)
            while select.select([fd], [], [], 0)[0] and (chunk := os.read(fd, 1 << 16)):
                chunks.append(chunk)
            return b"".join(chunks), False, status


def _kill_and_reap(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass


def _ending(status: int) -> str:
    """How a process that sent no result ended, in words."""
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        try:
            name = signal.Signals(number).name
        except ValueError:
            name = f"signal {number}"
        hint = " (the kernel's out-of-memory killer sends it too)" if number == signal.SIGKILL else ""
        return f"killed by {name} ({number}){hint}"
    if os.WIFEXITED(status):
        return f"exited with code {os.WEXITSTATUS(status)}"
    return f"ended with status {status}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, someone else's
        pass
    return True


def _address_space() -> int | None:
    """This process's current address space in bytes (Linux's /proc), or None."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def _limit_address_space(memory_bytes: int) -> None:  # pragma: no cover - in the child
    now = _address_space()
    if now is None:
        return
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = int(now + memory_bytes)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    try:  # the hard limit too, so that the function cannot raise its own
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ValueError, OSError):
        pass


def _limit_text(memory_bytes: int | None) -> str:
    return "no limit set" if memory_bytes is None else f"limit {memory_bytes / 2**30:.2f} GiB beyond the worker's"


def _flush(stream) -> None:
    try:
        stream.flush()
    except (OSError, ValueError, AttributeError):
        pass
