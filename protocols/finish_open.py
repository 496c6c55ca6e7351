"""How a writer finishes its file: the reopen for its final attributes (``status``), and the
one line when the file cannot be closed at all (:func:`not_closed`).

A run file and a study output are written under SWMR, which forbids changing attributes, so
their writer closes the file and opens it again to set the final ``status``. A reader following
the run (``biafc figures`` on a live run, a script polling it) holds HDF5's shared lock for the
moment of its read, and that reopen then failed ("unable to lock file"): the status stayed
``running`` while the run was reported complete. :func:`open_to_finish` waits for such readers,
then writes without the lock: the status is always written.
"""

from __future__ import annotations

import errno
import time
from pathlib import Path

import h5py

from protocols.one_line import first_line

__all__ = ["not_closed", "open_to_finish"]

#: how long a writer waits for readers' locks before it writes without the lock (s)
READERS_WAIT_S = 5.0


def _locked(exc: OSError) -> bool:
    return exc.errno in (errno.EAGAIN, errno.EACCES) or "unable to lock file" in str(exc)


def open_to_finish(path: str | Path, wait_s: float | None = None) -> h5py.File:
    """``h5py.File(path, "r+")`` for a writer's last attributes: retried while readers hold the
    file's lock, for ``wait_s`` s at most (default :data:`READERS_WAIT_S`), then opened without
    HDF5's file lock (readers only read; the attributes are written whole before the file
    closes)."""
    deadline = time.monotonic() + (READERS_WAIT_S if wait_s is None else wait_s)
    while True:
        try:
            return h5py.File(path, "r+", libver="latest")
        except OSError as exc:
            if not _locked(exc):
                raise
            if time.monotonic() >= deadline:
                return h5py.File(path, "r+", libver="latest", locking=False)
        time.sleep(0.02)


def not_closed(path: str | Path, exc: BaseException) -> str:
    """The one line of a writer whose file could not be closed (``exc``, most often a full
    disk): it leaves the file as a killed writer does, for ``biafc repair``."""
    return (
        f"{path}: the file could not be closed ({first_line(exc)}): it is left as a killed "
        f"writer's; free some space, then biafc repair {path}"
    )
