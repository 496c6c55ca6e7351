"""One writer per run file: a lock file ``RUN.h5.lock`` holding the writer's host and PID.

HDF5's own file locking does not help here: a resume clears the SWMR flags of a killed file
before it opens it, and a second process doing so under a live writer corrupts the file. So a
writer (a new run, a resume, ``biafc repair``) first creates ``RUN.h5.lock`` exclusively
(``O_CREAT | O_EXCL``) with its host, PID, process start time and command line. A second
writer is refused (:class:`FileInUse`, exit status 2) with a message naming the other process.
A lock left by a process that no longer runs on this host (killed, crashed) is stale and taken
over; a lock from another host is never taken over (its process cannot be checked from here):
the message says which file to delete once that run is known to be over.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["FileInUse", "RunFileLock", "in_use_by", "lock_path", "read_lock"]


class FileInUse(RuntimeError):
    """Another live process writes the run file (one line, names it)."""


def lock_path(path: str | Path) -> Path:
    p = Path(path)
    return p.with_name(p.name + ".lock")


def _start_time(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (Linux ``/proc``), else ``None``."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def _alive(pid: int, started: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by someone else
    now = _start_time(pid)
    return started is None or now is None or now == started  # else: the PID was reused


def read_lock(path: str | Path) -> dict[str, Any] | None:
    """The lock of run file ``path`` (``None`` when there is none or it is unreadable)."""
    try:
        return dict(json.loads(lock_path(path).read_text()))
    except (OSError, ValueError, TypeError):
        return None


def in_use_by(path: str | Path) -> str | None:
    """The one-line refusal when a live process holds the lock of ``path``, else ``None``
    (for a check before anything is connected; the writer still takes the lock itself)."""
    other = read_lock(path)
    if other is None:
        return None
    lock = RunFileLock(path)
    return None if lock._stale(other) else lock._in_use(other)


class RunFileLock:
    """The lock of one run file; :meth:`acquire` before writing, :meth:`release` after.

    ``stale_note`` tells, after :meth:`acquire`, whose stale lock was taken over (or "").
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.lock = lock_path(self.path)
        self.held = False
        self.stale_note = ""

    def _info(self) -> dict[str, Any]:
        return {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "process_start": _start_time(os.getpid()),
            "since": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "command": " ".join(sys.argv)[:500],
        }

    def acquire(self) -> RunFileLock:
        """Take the lock or raise :class:`FileInUse` naming the process that holds it."""
        self.lock.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(20):
            try:
                fd = os.open(self.lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                other = read_lock(self.path)
                if other is None:  # being written this instant, or garbage
                    time.sleep(0.05)
                    other = read_lock(self.path)
                    if other is None and self.lock.exists():
                        age = time.time() - self.lock.stat().st_mtime
                        if age < 2.0:
                            continue
                if other is not None and not self._stale(other):
                    raise FileInUse(self._in_use(other)) from None
                self.stale_note = "taken over a stale lock" + (
                    f" of process {other.get('pid')} on {other.get('host')} "
                    f"(since {other.get('since')})"
                    if other
                    else ""
                )
                self.lock.unlink(missing_ok=True)
                continue
            with os.fdopen(fd, "w") as f:
                json.dump(self._info(), f)
            self.held = True
            return self
        raise FileInUse(f"{self.path}: cannot take its lock {self.lock}")

    @staticmethod
    def _stale(other: dict[str, Any]) -> bool:
        if other.get("host") != socket.gethostname():
            return False
        try:
            pid = int(other.get("pid", -1))
        except (TypeError, ValueError):
            return True
        if pid == os.getpid():
            return False
        return not _alive(pid, other.get("process_start"))

    def _in_use(self, other: dict[str, Any]) -> str:
        where = other.get("host", "?")
        here = where == socket.gethostname()
        tail = (
            "wait for it to end or stop it" if here else f"if that run is over, delete {self.lock}"
        )
        return (
            f"{self.path} is being written by process {other.get('pid')} on {where} "
            f"(since {other.get('since')}: {other.get('command', '')!s:.80}); {tail}"
        )

    def release(self) -> None:
        """Remove the lock if this process holds it."""
        if not self.held:
            return
        other = read_lock(self.path)
        if other is None or int(other.get("pid", -1)) == os.getpid():
            self.lock.unlink(missing_ok=True)
        self.held = False

    def __enter__(self) -> RunFileLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
