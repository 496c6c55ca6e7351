"""Files a writer had to leave open, and how a process ends with them.

After a failed write on a full disk HDF5 can no longer close the file: closing it raises, and
HDF5's own clean-up at the process's exit then crashes the process (status 139, "Segmentation
fault" on the terminal), whatever Python did before. A writer that gives up on its file
(:class:`protocols.runfile.RunFileWriter`, :class:`protocols.studyfile.StudyStore`) therefore
names it to :func:`leave_open`, and a program that ends (the CLIs, the bench window) asks
:func:`files_left_open` and ends through :func:`exit_leaving_them`: its logs flushed, its exit
status its own, Python's exit handlers run, HDF5's clean-up skipped. The file is then as a
killed writer leaves it, for ``run_protocol --resume`` or ``biafc repair``.

The handle itself is not kept: once released, the same process can open the file again (the
bench window can show what was measured, ``biafc repair`` can run in it); h5py reports the
failed release as an ignored exception on the standard error, and the crash at the exit comes
whether or not it was released.
"""

from __future__ import annotations

import atexit
import logging
import os
import sys
from pathlib import Path
from typing import NoReturn

__all__ = ["exit_leaving_them", "files_left_open", "leave_open"]

#: the files left open by this process, in the order they were left
_LEFT: list[str] = []


def leave_open(path: str | Path) -> None:
    """Remember that this process left the file at ``path`` open after a failed write, so it
    must end without HDF5's clean-up."""
    if str(path) not in _LEFT:
        _LEFT.append(str(path))


def files_left_open() -> tuple[str, ...]:
    """The paths of the files left open by this process, in the order they were left."""
    return tuple(_LEFT)


def exit_leaving_them(code: int) -> NoReturn:
    """End the process with ``code`` without HDF5's clean-up. Python's own ``atexit`` handlers
    run first (logging's shutdown, which flushes and closes the log files; the stability
    verdicts written to the cache), then the standard streams are flushed: HDF5's clean-up is
    the C library's, after them, and is what is skipped."""
    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)  # CPython's, since Python 2
    if run_exit_handlers is not None:
        run_exit_handlers()
    logging.shutdown()  # where the above is missing; a second call changes nothing
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # the terminal is gone, or the stream closed
            pass
    os._exit(int(code))
