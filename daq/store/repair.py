"""``biafc repair RUN.h5``: make a run file left by a killed writer readable by any HDF5 reader.

A writer killed (SIGKILL, power cut) leaves the superblock's "open for write" flags set, and
plain ``h5py.File(path)`` or HDFView refuse the file ("may use h5clear"). Every point was
flushed, so nothing is lost: :func:`repair_run` takes the file's lock (refused while a live
process writes it), clears the flags (as ``h5clear -s``), marks a run that was still
``running`` as ``aborted`` with a log row saying what was kept, removes the killed writer's
leftovers (its stale lock, a half-made ``.NAME.PID.part``), and checks that plain h5py opens
the result and sees the same points.

A design study's output (``biafc study``, :mod:`protocols.studyfile`) is written the same way
and repaired the same way: flags cleared, a study still ``running`` marked ``incomplete`` (run
the same ``biafc study`` command again to continue it), every finished cell kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from daq.store.lock import RunFileLock
from daq.store.process_check import process_alive
from daq.store.run_store import StoreError
from protocols.outputfile import read_output
from protocols.recover import clear_consistency_flags, has_consistency_flags, has_stale_end
from protocols.runfile import (
    DamagedRecordsError,
    PointState,
    RunData,
    RunFileError,
    RunFileWriter,
    read_run,
)
from protocols.studyfile import StudyData, StudyFileError, read_study
from protocols.studyformat import DamagedCellsError

__all__ = ["RepairReport", "repair_run"]


@dataclass
class RepairReport:
    """What :func:`repair_run` found and did."""

    path: Path
    status_before: str
    status_after: str
    n_done: int
    n_failed: int
    n_pending: int
    actions: list[str] = field(default_factory=list)
    #: what was counted: "point(s) measured" (a run file) or "cell(s) run" (a study output)
    counted: str = "point(s) measured"

    def line(self) -> str:
        did = "; ".join(self.actions) if self.actions else "nothing to repair"
        return (
            f"{self.path}: {did}; {self.n_done} {self.counted}, {self.n_failed} failed, "
            f"{self.n_pending} pending; status {self.status_after}; opens with plain h5py"
        )


def _counts(path: Path) -> tuple[int, int, int]:
    return _run_counts(read_run(path))


def _run_counts(run: RunData) -> tuple[int, int, int]:
    """``(measured, failed, pending)`` points of ``run``."""
    done = [s.done for s in run.scans.values()]
    n_done = sum(int(np.sum(d == PointState.DONE)) for d in done)
    n_failed = sum(int(np.sum(d == PointState.FAILED)) for d in done)
    return n_done, n_failed, sum(d.size for d in done) - n_done - n_failed


def _leftovers(path: Path) -> list[Path]:
    """Half-made ``.NAME.PID.part`` files of writers that no longer run."""
    out = []
    for part in path.parent.glob(f".{path.name}.*.part"):
        try:
            pid = int(part.name[len(path.name) + 2 : -len(".part")])
        except ValueError:
            continue
        if not process_alive(pid, None):
            out.append(part)
    return out


def _rebuild(path: Path) -> None:
    """Copy every attribute and object of ``path`` into a new file, then put it in its place
    (the copy is complete before the original is replaced)."""
    import os

    tmp = path.with_name(f".{path.name}.{os.getpid()}.repair")
    try:
        with h5py.File(path, "r") as src, h5py.File(tmp, "w", libver="latest") as dst:
            for key, value in src.attrs.items():
                dst.attrs[key] = value
            for name in src:
                src.copy(src[name], dst, name=name)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def repair_run(path: str | Path) -> RepairReport:
    """Repair ``path`` in place (see the module); raises :class:`StoreError` (one line) when
    it is not a run file or another process writes it."""
    from daq.store.lock import FileInUse

    path = Path(path)
    if not path.is_file():
        raise StoreError(
            f"{path} is a folder; give a run file (RUN.h5)"
            if path.is_dir()
            else f"{path} does not exist"
        )
    lock = RunFileLock(path)
    try:
        lock.acquire()
    except FileInUse as exc:
        raise StoreError(str(exc)) from None
    try:
        actions = [lock.stale_note] if lock.stale_note else []
        status_first = None
        try:
            data = _read(path)
        except DamagedRecordsError:  # points damaged on disk: cleared, to be measured again
            status_first = _clear_damaged(path, actions, _clear_records)
            data = _read(path)
        except DamagedCellsError:  # a study's cells damaged on disk: cleared, to be run again
            status_first = _clear_damaged(path, actions, _clear_cells)
            data = _read(path)
        if isinstance(data, StudyData):
            return _repair_study(path, data, actions, status_first)
        before_counts = _run_counts(data)
        status_before = status_first or data.status
        _clear_superblock(path, actions)
        status_after = data.status
        if data.status == "running":
            try:
                writer = RunFileWriter.open_existing(path, swmr=False, resumed=False)
            except (OSError, RuntimeError) as exc:
                # killed while writing metadata outside SWMR (closing): the data reads, but
                # the file takes no more writes; copy every object into a fresh file
                _rebuild(path)
                actions.append(f"rebuilt the file (it took no writes: {str(exc)[:60]})")
                writer = RunFileWriter.open_existing(path, swmr=False, resumed=False)
            n_done, n_failed, n_pending = before_counts
            writer.log(
                "error",
                "repaired: the writer did not close the file (it was killed, or its disk "
                f"filled or its folder turned read-only); {n_done} point(s) kept, {n_failed} "
                f"failed, {n_pending} pending (continue with --resume)",
            )
            writer.close(
                "aborted",
                stamp="repaired",
                outcome="run aborted: the writer did not close the file (repaired)",
            )
            status_after = "aborted"
            actions.append("marked the run aborted (it was still 'running')")
        for part in _leftovers(path):
            part.unlink(missing_ok=True)
            actions.append(f"removed the half-made {part.name}")
        with h5py.File(path, "r") as f:  # what any reader does
            if f.attrs.get("format") != "biafc-run":
                raise StoreError(f"{path}: not readable after the repair")
        after_counts = _counts(path)
        if after_counts != before_counts:
            raise StoreError(f"{path}: points changed during the repair {before_counts}")
        return RepairReport(path, status_before, status_after, *after_counts, actions=actions)
    finally:
        lock.release()


def _study_counts(data: StudyData) -> tuple[int, int, int]:
    """``(run, failed, pending)`` cells of ``data``."""
    from analysis.study_cells import STATUS_FAILED

    status = data.status
    n_failed = int(np.sum(status == STATUS_FAILED))
    n_pending = int(np.sum(status == 0))
    return status.size - n_failed - n_pending, n_failed, n_pending


def _read(path: Path) -> RunData | StudyData:
    """The whole file, once (a damaged one waits its grace once: protocols.outputfile); one
    line when it does not read, but records or cells damaged on disk
    (:class:`~protocols.runfile.DamagedRecordsError`,
    :class:`~protocols.studyformat.DamagedCellsError`) pass."""
    try:
        return read_output(path, spectra=False)
    except (DamagedRecordsError, DamagedCellsError):
        raise
    except StudyFileError as exc:
        raise StoreError(f"{path} is not a readable biafc study output ({exc})") from None
    except (OSError, RunFileError) as exc:
        raise StoreError(f"{path} is not a readable biafc run file ({exc})") from None


def _clear_superblock(path: Path, actions: list[str]) -> None:
    """Clear a killed writer's flags and raise a stale end-of-file address (each said in
    ``actions``): bytes flushed past it are otherwise unreadable, and a writer allocates over
    them."""
    flags, stale = has_consistency_flags(path), has_stale_end(path)
    if (flags or stale) and clear_consistency_flags(path):
        if flags:
            actions.append("cleared the open-for-write flags of a killed writer")
        if stale:
            actions.append(
                "raised the file's end address over the bytes a killed writer flushed past it"
            )


def _clear_damaged(path: Path, actions: list[str], clear: Callable[[Path], str | None]) -> str:
    """Clear what ``clear`` finds damaged on disk in ``path`` (run records or study cells),
    after a killed writer's flags (each noted in ``actions``). Returns the file's status
    before."""
    _clear_superblock(path, actions)
    with h5py.File(path, "r") as f:
        status = str(f.attrs.get("status", ""))
    line = clear(path)
    if line is not None:
        actions.append(line.removeprefix("repaired: "))
    return status


def _clear_records(path: Path) -> str:
    """:mod:`protocols.damaged_records`: the points of run file ``path`` whose records fail
    their checksum, cleared to be measured again."""
    from protocols.damaged_records import clear_damaged_points, damaged_points

    return clear_damaged_points(path, damaged_points(path))


def _clear_cells(path: Path) -> str | None:
    """:mod:`protocols.damaged_cells`: the cells of study output ``path`` whose results fail
    their checksum, cleared to be run again."""
    from protocols.damaged_cells import clear_damaged_cells

    return clear_damaged_cells(path)


def _repair_study(
    path: Path, data: StudyData, actions: list[str], status_first: str | None = None
) -> RepairReport:
    """:func:`repair_run` of a study output read as ``data`` (the caller holds its lock;
    ``status_first``: its status before damaged cells were cleared, if any were)."""
    before_counts = _study_counts(data)
    status_now = str(data.attrs.get("status", ""))
    status_before = status_first or status_now
    _clear_superblock(path, actions)
    status_after = status_now
    if status_now == "running":
        try:
            f = h5py.File(path, "r+", libver="latest")
        except OSError as exc:  # killed while writing metadata: copy every object
            _rebuild(path)
            actions.append(f"rebuilt the file (it took no writes: {str(exc)[:60]})")
            f = h5py.File(path, "r+", libver="latest")
        with f:
            f.attrs["status"] = "incomplete"
        status_after = "incomplete"
        actions.append(
            "marked the study incomplete (it was still 'running'; run it again to continue)"
        )
    for part in _leftovers(path):
        part.unlink(missing_ok=True)
        actions.append(f"removed the half-made {part.name}")
    with h5py.File(path, "r") as f:  # what any reader does
        if f.attrs.get("format") != "biafc-study":
            raise StoreError(f"{path}: not readable after the repair")
    after_counts = _study_counts(read_study(path, spectra=False))
    if after_counts != before_counts:
        raise StoreError(f"{path}: cells changed during the repair {before_counts}")
    return RepairReport(
        path, status_before, status_after, *after_counts, actions=actions, counted="cell(s) run"
    )
