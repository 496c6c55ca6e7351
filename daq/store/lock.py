"""One writer per run file: a lock file ``RUN.h5.lock`` holding the writer's host and PID.

HDF5's own file locking does not help here: a resume clears the SWMR flags of a killed file
before it opens it, and a second process doing so under a live writer corrupts the file. So a
writer (a new run, a resume, ``biafc repair``, ``biafc study``) first publishes ``RUN.h5.lock``
with its host, PID, process start time and command line. A second writer is refused
(:class:`FileInUse`, exit status 2) with a message naming the other process.

The lock is published whole: its content is written (and synced) to a temporary file of this
process in the same folder, which is then hard-linked to the lock's name (``os.link`` fails
if the name exists, so exactly one writer wins) and removed. A lock file therefore never exists
without its content, whatever moment a writer is killed or preempted at. (On a file system
without hard links the lock is created with ``O_CREAT | O_EXCL`` and then written, as before.)

A lock left by a process that no longer runs on this host (killed, crashed; asked without
signalling it, :mod:`daq.store.process_check`) is stale and taken over; a lock from another
host is never taken over (its process cannot be checked from here): the message says which
file to delete once that run is known to be over. A takeover holds an
``flock`` on the stale lock file itself while it checks that the name still points to that
file, reads it again and removes it, so two processes taking over the same stale lock at once
cannot both win (the second finds the name now points elsewhere and looks again). An empty or
unreadable lock (left by an older version, which created the file before writing it, or made
by hand) is waited for :data:`UNREADABLE_GRACE_S` and then taken over the same way.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any

from daq.store.process_check import process_alive, process_start

try:
    import fcntl
except ImportError:  # not on Windows: a takeover there is checked without the flock
    fcntl = None  # type: ignore[assignment]

__all__ = ["FileInUse", "LockNotWritable", "RunFileLock", "in_use_by", "lock_path", "read_lock"]

#: an empty or unreadable lock younger than this (s, by its modification time) may still be
#: being written by an older version of this module; it is waited for, then taken over
UNREADABLE_GRACE_S = 2.0


def _write_synced(fd: int, content: bytes) -> None:
    """Write ``content`` to ``fd``, sync it to disk and close it (a power cut leaves a whole lock
    or none)."""
    with os.fdopen(fd, "wb") as f:
        f.write(content)
        f.flush()
        os.fsync(f.fileno())


class FileInUse(RuntimeError):
    """Another live process writes the run file (one line, names it)."""


class LockNotWritable(FileInUse):
    """The lock cannot be written beside the file (its folder is read-only to this user): a
    writer is refused as for a file in use, in one line naming the folder. ``cause``: the
    system's error."""

    def __init__(self, message: str, cause: OSError) -> None:
        super().__init__(message)
        self.cause = cause


def lock_path(path: str | Path) -> Path:
    p = Path(path)
    return p.with_name(p.name + ".lock")


def read_lock(path: str | Path) -> dict[str, Any] | None:
    """The lock of run file ``path`` (``None`` when there is none or it is unreadable)."""
    try:
        return dict(json.loads(lock_path(path).read_text()))
    except (OSError, ValueError, TypeError):
        return None


def command_shown(info: dict[str, Any]) -> str:
    """The holder's command line as it names the run: its end kept (it was cut at 80
    characters, which dropped the run file's name)."""
    text = str(info.get("command", ""))
    return text if len(text) <= 160 else "..." + text[-157:]


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
            "process_start": process_start(os.getpid()),
            "since": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "command": " ".join(sys.argv)[:500],
        }

    def acquire(self) -> RunFileLock:
        """Take the lock or raise :class:`FileInUse` naming the process that holds it
        (:class:`LockNotWritable` where the lock cannot be written at all)."""
        try:
            return self._acquire()
        except OSError as exc:  # the folder read-only to this user, or gone
            raise LockNotWritable(
                f"{self.path}: cannot write its lock {self.lock.name} in {self.lock.parent} "
                f"({exc.strerror or exc}); whatever writes the file needs that folder "
                "writable (or copy the file to a folder you can write)",
                exc,
            ) from None

    def _acquire(self) -> RunFileLock:
        self.lock.parent.mkdir(parents=True, exist_ok=True)
        self._remove_dead_temps()
        content = json.dumps(self._info()).encode()
        deadline = time.monotonic() + UNREADABLE_GRACE_S + 1.0
        while time.monotonic() < deadline:
            if self._publish(content):
                self.held = True
                return self
            other, unreadable_age = self._look()
            if other is not None and not self._stale(other):
                raise FileInUse(self._in_use(other))
            if other is None and unreadable_age is None:
                continue  # gone meanwhile (released, or taken over by another): try again
            if unreadable_age is not None and unreadable_age < UNREADABLE_GRACE_S:
                time.sleep(0.05)  # may be an older version's lock, being written
                continue
            note = self._take_over_stale()
            if note is not None:
                self.stale_note = note
        raise FileInUse(
            f"{self.path}: cannot take its lock {self.lock} (it stays empty or unreadable); "
            "if no run writes this file, delete the lock"
        )

    def _publish(self, content: bytes) -> bool:
        """Create the lock with ``content`` in one step; False when the name is taken."""
        tmp = self.lock.with_name(f".{self.lock.name}.{os.getpid()}-{os.urandom(4).hex()}.tmp")
        try:
            _write_synced(os.open(tmp, os.O_CREAT | os.O_TRUNC | os.O_WRONLY, 0o644), content)
            try:
                os.link(tmp, self.lock)  # fails if the name exists: one writer wins
                return True
            except FileExistsError:
                return False
            except OSError:  # a file system without hard links: create, then write
                return self._publish_without_links(content)
        finally:
            tmp.unlink(missing_ok=True)

    def _publish_without_links(self, content: bytes) -> bool:
        try:
            fd = os.open(self.lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            return False
        _write_synced(fd, content)
        return True

    def _remove_dead_temps(self) -> None:
        """Remove the temporary lock files of writers killed while publishing."""
        for tmp in self.lock.parent.glob(f".{self.lock.name}.*.tmp"):
            try:
                pid = int(tmp.name[len(self.lock.name) + 2 :].split("-", 1)[0])
            except ValueError:
                continue
            if pid != os.getpid() and not process_alive(pid, None):
                tmp.unlink(missing_ok=True)

    def _look(self) -> tuple[dict[str, Any] | None, float | None]:
        """``(content, None)`` of the lock; ``(None, age in s)`` when it is there but empty or
        unreadable; ``(None, None)`` when it is gone."""
        try:
            st = os.stat(self.lock)
        except FileNotFoundError:
            return None, None
        other = read_lock(self.path)
        if other is not None:
            return other, None
        if not self.lock.exists():
            return None, None
        return None, max(0.0, time.time() - st.st_mtime)

    def _take_over_stale(self) -> str | None:
        """Remove the lock if it is (still) stale or unreadable, under an ``flock`` of that
        very file, so that of two processes taking it over at once only one removes it (the
        other then finds the name gone or pointing to the winner's lock). Returns the note
        to log, or ``None`` when nothing was removed (look again)."""
        try:
            try:  # writable where it can be: NFS emulates flock with locks that need it
                fd = os.open(self.lock, os.O_RDWR)
            except PermissionError:
                fd = os.open(self.lock, os.O_RDONLY)
        except FileNotFoundError:
            return None
        try:
            if fcntl is not None:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX)
                except OSError:  # a file system without flock: checked below, unguarded
                    pass
            try:
                if os.stat(self.lock).st_ino != os.fstat(fd).st_ino:
                    return None  # removed and published again meanwhile
            except FileNotFoundError:
                return None
            raw = os.read(fd, 1 << 16)
            try:
                other: dict[str, Any] | None = dict(json.loads(raw))
            except (ValueError, TypeError):
                other = None
            if other is None:
                age = time.time() - os.fstat(fd).st_mtime
                if age < UNREADABLE_GRACE_S:
                    return None
            elif not self._stale(other):
                return None  # the loop looks again and names its holder
            os.unlink(self.lock)
        finally:
            os.close(fd)  # also releases the flock
        if other is None:
            return "taken over an empty or unreadable lock"
        return (
            f"taken over a stale lock of process {other.get('pid')} on {other.get('host')} "
            f"(since {other.get('since')})"
        )

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
        return not process_alive(pid, other.get("process_start"))

    def _in_use(self, other: dict[str, Any]) -> str:
        where = other.get("host", "?")
        here = where == socket.gethostname()
        tail = (
            "wait for it to end or stop it" if here else f"if that run is over, delete {self.lock}"
        )
        return (
            f"{self.path} is being written by process {other.get('pid')} on {where} "
            f"(since {other.get('since')}: {command_shown(other)}); {tail}"
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
