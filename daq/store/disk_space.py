"""Room on the disk for a run's data: checked before a run starts and before every point.

A disk that filled during a run did not stop it. HDF5 writes a point's records when it evicts
them from its chunk cache, and a write that fails there is reported only to Python's "exception
ignored" hook. So the run went on, each point marked measured over records that never reached
the disk (read back as NaN, the fill value), until a flush of the file's own metadata failed.
Then the process crashed at exit. Now:
- a request whose points cannot fit the free space is refused before anything moves
  (:func:`shortfall`, from :func:`daq.request.validate_request`);
- the engine checks the room before each point and ends the run, failed, when one more point
  and :data:`MARGIN_BYTES` no longer fit, every measured point kept for ``--resume``;
- the writer flushes a point's records before it marks the point measured
  (:meth:`protocols.runfile.RunFileWriter.write_point`): a write that fails anyway refuses
  the point.

A design study's output (``biafc study``) is checked before each task's write
(:func:`room_for_a_task`) and written the same way
(:meth:`protocols.studyfile.StudyStore.write_task`).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from daq.store.writable import nearest_existing

__all__ = [
    "MARGIN_BYTES",
    "DiskFull",
    "free_bytes",
    "no_margin",
    "point_bytes",
    "room_for_a_point",
    "room_for_a_task",
    "shortfall",
]

#: kept free beyond the points' records (bytes): the file's own structure, its log rows and
#: closing, ``RUN.log``, and room for the rest of the system
MARGIN_BYTES = 16 * 2**20


class DiskFull(OSError):
    """The run file's disk has no room for the next point (the message is one line)."""


def point_bytes(samples: int) -> int:
    """Bytes of one point's records: velocity and drive, ``samples`` each, float32."""
    return 2 * 4 * samples


def free_bytes(path: str | Path) -> int | None:
    """Free bytes for an unprivileged writer on the disk of ``path`` (a file, or where it will
    be: its nearest existing folder), ``None`` where that cannot be asked."""
    try:
        return shutil.disk_usage(nearest_existing(Path(path).absolute())).free
    except OSError:
        return None


def _mb(n: float) -> str:
    return f"{n / 2**20:.3g} MB"


def shortfall(path: str | Path, n_points: int, samples: int) -> str | None:
    """Why ``n_points`` points of ``samples`` samples cannot be written to ``path`` (one line
    naming the file, what the points need and what is free), or ``None`` when they fit with
    :data:`MARGIN_BYTES` to spare (or the free space cannot be asked)."""
    free = free_bytes(path)
    if free is None or n_points <= 0:
        return None
    need = n_points * point_bytes(samples) + MARGIN_BYTES
    if free >= need:
        return None
    return (
        f"{path}: {n_points:,} point(s) need {_mb(need)} ({n_points:,} x {samples:,} samples x 2 "
        f"channels x 4 bytes, and {_mb(MARGIN_BYTES)} to spare) but its disk has {_mb(free)} "
        "free; free some space or write the run elsewhere"
    )


def no_margin(path: str | Path) -> str | None:
    """Why no output should be started on the disk of ``path``: less than
    :data:`MARGIN_BYTES` free (one line), else ``None``. HDF5 may leave a file it creates on a
    full disk unreadable (a design study's output, whose size is not known before)."""
    free = free_bytes(path)
    if free is None or free >= MARGIN_BYTES:
        return None
    return (
        f"{path}: its disk has {_mb(free)} free, and {_mb(MARGIN_BYTES)} are kept to spare: "
        "free some space or write the output elsewhere"
    )


def room_for_a_task(path: str | Path, n_kept: int) -> None:
    """Raise :class:`DiskFull` when the disk of study output ``path`` has less than
    :data:`MARGIN_BYTES` free (a task's numbers are far smaller); ``n_kept`` cells are in it."""
    free = free_bytes(path)
    if free is not None and free < MARGIN_BYTES:
        raise DiskFull(
            f"the disk of {path} is full: {_mb(free)} free, a study keeps {_mb(MARGIN_BYTES)} "
            f"to spare; {n_kept} cell(s) kept: free some space, then run the study again to "
            "continue"
        )


def room_for_a_point(path: str | Path, samples: int, n_kept: int) -> None:
    """Raise :class:`DiskFull` when the disk of ``path`` has no room for one more point of
    ``samples`` samples and :data:`MARGIN_BYTES`; ``n_kept`` points are in the file."""
    free = free_bytes(path)
    need = point_bytes(samples) + MARGIN_BYTES
    if free is not None and free < need:
        raise DiskFull(
            f"the disk of {path} is full: {_mb(free)} free, the next point needs {_mb(need)} "
            f"with the margin; {n_kept} point(s) kept: free some space, then "
            f"run_protocol --resume {path}"
        )
