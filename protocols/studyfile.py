"""The study output (HDF5): every cell's parameters and metrics, written task by task.

Layout (``format = "biafc-study"``, ``format_version = 1`` on the root)::

    /                     attrs: name, study_yaml (the study file's text), study_digest (sha256
                          of what decides the results, with the base chain), chain_yaml,
                          n_cells, amplitude_kind, directions, status (running | complete |
                          incomplete | failed), created_utc, software, model_version (the DEM
                          kernel's and the modes' versions that ran the cells), model_changes_json
                          (continues accepted with --accept-model-change: from, to, cells_done)
    /parameters/<name>    [n_cells] float64, SI (attr unit); amplitude last
    /cells/point          [n_cells] int64: the design point of each cell
    /cells/status         [n_cells] int8: 0 not run, 1 ok, 2 inaccurate (above max_error),
                          3 failed (metrics NaN; /cells/message says why)
    /cells/message        [n_cells] str
    /metrics/<name>       [n_cells] float64, NaN until run (attrs unit, description)
    /spectra/freq_Hz      [F] (only with record_spectra); /spectra/<dir> [n_cells, F] float32
    (status, metrics and spectra: chunked, each chunk with a Fletcher-32 checksum that HDF5
    checks at every read; outputs before 2026-11-27 have none)
    /tasks/wall_s         [n_tasks] float64 (NaN until run); /tasks/worker [n_tasks] str;
                          attr cells_per_task: the grouping the task numbers count in
    /tasks_earlier/<k>    the /tasks of an earlier run with another cells_per_task (k = 0, 1,
                          ...): a study continued with another grouping keeps them aside

Writing follows the run files' discipline (:mod:`protocols.runfile`): the layout is made under a
temporary name and renamed once complete, then written in SWMR mode (``libver="latest"``), so a
writer killed at any moment (SIGKILL, power cut) leaves a file whose every flushed task reads
back. A task's metrics, spectra and messages are written and flushed first, its cells' status
after, flushed again: a cell whose status is not 0 is complete, so a resume
(:meth:`StudyStore.open`, which clears a killed writer's open-for-write flags as ``--resume``
does) skips it. One writer per file: the caller holds :class:`daq.store.lock.RunFileLock`.
``biafc repair`` makes a killed output readable by plain h5py. The client never holds more
than the parameter table and the task in hand.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from protocols.finish_open import not_closed, open_to_finish
from protocols.left_open import leave_open
from protocols.one_line import first_line
from protocols.study import METRICS, PARAMETERS, CellTable
from protocols.studyformat import FORMAT, FORMAT_VERSION, DamagedCellsError, StudyFileError

__all__ = [
    "FORMAT",
    "STATUS_FAILED",
    "STATUS_INACCURATE",
    "STATUS_NOT_RUN",
    "STATUS_OK",
    "StudyData",
    "StudyFileError",
    "StudyStore",
    "is_study_file",
    "read_open_study",
    "read_study",
]

#: /cells/status codes (the layout above)
STATUS_NOT_RUN = 0
STATUS_OK = 1
STATUS_INACCURATE = 2
STATUS_FAILED = 3


def _unit(name: str) -> str:
    if name == "amplitude":
        return ""
    if name in PARAMETERS:
        return PARAMETERS[name].unit
    base = name.rsplit("_", 1)[0] if name.endswith(("_ltr", "_rtl")) else name
    if base in METRICS:
        return METRICS[base][0]
    if base == "f_edge":
        return "Hz"
    return ""


def _description(name: str) -> str:
    base = name.rsplit("_", 1)[0] if name.endswith(("_ltr", "_rtl")) else name
    if base in METRICS:
        return METRICS[base][1]
    return {
        "f_edge": "the far cylinder's band edge where conversion saturates (Hz)",
        "error_estimate": "integrator's step-doubling error estimate (relative L2)",
        "alpha_actual": "the chain's asymmetry factor from its quasi-bands",
    }.get(base, "")


def is_study_file(path: str | Path) -> bool:
    """Whether ``path`` is an HDF5 study output (False for anything else, damaged included)."""
    from protocols.runfile import open_for_reading

    try:
        with open_for_reading(path) as f:  # also one being written, or left by a killed writer
            return bool(f.attrs.get("format") == FORMAT)
    except (OSError, ValueError, KeyError, RuntimeError):  # RunFileError is a ValueError
        return False


def _open_writer(path: Path) -> h5py.File:
    """``path`` opened to write tasks in SWMR mode (a file made before SWMR, whose superblock
    cannot take it, is written as it is)."""
    f = h5py.File(path, "r+", libver="latest")
    try:
        f.swmr_mode = True
    except (ValueError, RuntimeError, OSError):
        pass
    return f


class StudyStore:
    """The writer of one study output (:meth:`create` or :meth:`open` to resume)."""

    def __init__(self, path: Path, f: h5py.File) -> None:
        self.path = path
        self.f = f
        #: why the output took no more writes (a task's write failed: a full disk), else None
        self.broken: str | None = None

    @classmethod
    def create(
        cls,
        path: str | Path,
        *,
        name: str,
        study_yaml: str,
        digest: str,
        chain_yaml: str,
        table: CellTable,
        directions: Sequence[str],
        metric_names: Sequence[str],
        n_tasks: int,
        spectrum_freq_Hz: NDArray[np.float64] | None = None,
        cells_per_task: int | None = None,
        model_version: str,
    ) -> StudyStore:
        """Make a new output (``model_version``: :func:`sim_backend.dem.versions.model_version`
        of the software that runs its cells; a continue with another is refused)."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.part")
        tmp.unlink(missing_ok=True)
        f = h5py.File(tmp, "w", libver="latest")
        try:
            f.attrs.update(
                {
                    "format": FORMAT,
                    "format_version": FORMAT_VERSION,
                    "name": name,
                    "study_yaml": study_yaml,
                    "study_digest": digest,
                    "chain_yaml": chain_yaml,
                    "n_cells": table.n_cells,
                    "amplitude_kind": table.amplitude_kind,
                    "directions": json.dumps(list(directions)),
                    "status": "running",
                    "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "software": _software(),
                    "model_version": model_version,
                }
            )
            n = table.n_cells
            chunk = (min(n, 4096),)
            g = f.create_group("parameters")
            for i, pname in enumerate(table.names):
                ds = g.create_dataset(pname, data=table.values[:, i])
                unit = ("m" if table.amplitude_kind == "displacement" else "N") if (
                    pname == "amplitude") else _unit(pname)  # fmt: skip
                ds.attrs["unit"] = unit
            g.attrs["order"] = json.dumps(list(table.names))
            c = f.create_group("cells")
            c.create_dataset("point", data=table.point)
            # the per-cell results carry HDF5's Fletcher-32 checksum, a chunk each, checked at every
            # read: bytes damaged on disk are refused (one_line_errors), not read as results
            c.create_dataset("status", shape=(n,), dtype="i1", fillvalue=0, chunks=chunk,
                             fletcher32=True)  # fmt: skip
            c.create_dataset("message", shape=(n,), dtype=h5py.string_dtype(), chunks=chunk)
            m = f.create_group("metrics")
            for mname in metric_names:
                ds = m.create_dataset(mname, shape=(n,), dtype="f8", fillvalue=np.nan, chunks=chunk,
                                      fletcher32=True)  # fmt: skip
                ds.attrs["unit"] = _unit(mname)
                ds.attrs["description"] = _description(mname)
            m.attrs["order"] = json.dumps(list(metric_names))
            if spectrum_freq_Hz is not None:
                s = f.create_group("spectra")
                s.create_dataset("freq_Hz", data=spectrum_freq_Hz).attrs["unit"] = "Hz"
                for d in directions:
                    s.create_dataset(
                        d, shape=(n, spectrum_freq_Hz.size), dtype="f4", fillvalue=np.nan,
                        chunks=(min(n, 64), spectrum_freq_Hz.size), fletcher32=True,
                    ).attrs["unit"] = "m"  # fmt: skip
            _create_tasks(f, n_tasks, cells_per_task)
            f.flush()
            f.close()
        except BaseException:
            f.close()
            tmp.unlink(missing_ok=True)
            raise
        tmp.replace(p)  # the caller holds the lock: no other writer makes this file
        return cls(p, _open_writer(p))

    @classmethod
    def open(
        cls,
        path: str | Path,
        *,
        digest: str,
        table: CellTable,
        n_tasks: int | None = None,
        cells_per_task: int | None = None,
        model_version: str | None = None,
        accept_model_change: bool = False,
    ) -> StudyStore:
        """Open an output to continue it; refused (:class:`StudyFileError`) when it is not a
        study output, was made from another study (digest), holds other cells or (when
        ``model_version`` is given) was run by another model version, or by a version of this
        software that did not record it: its cells would mix with this run's (unless every
        cell is done: nothing would be added; or ``accept_model_change``: the change is
        recorded in ``model_changes_json`` and the output's ``model_version`` becomes this
        one). The caller holds
        the file's lock; the open-for-write flags a killed writer left are cleared first.
        ``n_tasks``, ``cells_per_task``: this run's grouping; when the output's ``/tasks`` counts
        in another (``run.cells_per_task`` edited between runs: the digest leaves ``run``
        out), it is kept aside as ``/tasks_earlier/<k>`` and a new ``/tasks`` is made (before,
        a grouping with more tasks wrote past its end: IndexError at every continue)."""
        from protocols.recover import clear_consistency_flags

        p = Path(path)
        try:
            clear_consistency_flags(p)  # as --resume of a run file: a killed writer's SWMR flags
            f = h5py.File(p, "r+", libver="latest")
        except OSError as exc:
            raise StudyFileError(f"{p}: cannot open to continue it ({exc})") from None
        try:
            if f.attrs.get("format") != FORMAT:
                raise StudyFileError(f"{p}: not a study output; choose another --out")
            old = str(f.attrs.get("study_digest", ""))
            if old != digest:
                raise StudyFileError(
                    f"{p}: made from another study (digest {old[:12]}, this one {digest[:12]}); "
                    "choose another --out"
                )
            same = int(f.attrs["n_cells"]) == table.n_cells and all(
                name in f["parameters"]
                and np.array_equal(f["parameters"][name][...], table.values[:, i])
                for i, name in enumerate(table.names)
            )
            if not same:
                raise StudyFileError(
                    f"{p}: holds other cells than this study's; choose another --out"
                )
            if model_version is not None and not np.all(f["cells/status"][...] != 0):
                _same_model(p, f, model_version, accept_model_change)  # last: it may write
            if n_tasks is not None:
                _regroup_tasks(f, n_tasks, cells_per_task)
        except BaseException:
            f.close()
            raise
        f.attrs["status"] = "running"  # attributes are set before SWMR starts
        f.flush()
        try:
            f.swmr_mode = True
        except (ValueError, RuntimeError, OSError):
            pass  # an output made before SWMR: written as it is
        return cls(p, f)

    @property
    def model_version(self) -> str:
        """The model version that ran this output's cells ("" where none was given)."""
        return str(self.f.attrs.get("model_version", ""))

    def done(self) -> NDArray[np.bool_]:
        """``[n_cells]``: cells already run (ok, inaccurate or failed)."""
        return np.asarray(self.f["cells/status"][...] != 0)

    def write_task(self, task: int, result: Any) -> None:
        """Write one :class:`analysis.study_cells.TaskResult` (cells sorted): its numbers, flushed,
        then its cells' status, flushed: a kill between the two leaves the task to run again."""
        idx = np.asarray(result.cells, dtype=np.int64)
        order = np.argsort(idx)
        idx = idx[order]
        contiguous = idx.size > 0 and idx[-1] - idx[0] + 1 == idx.size
        sel: Any = slice(int(idx[0]), int(idx[-1]) + 1) if contiguous else idx
        if self.broken is not None:
            raise StudyFileError(self.broken)
        try:
            written = []
            for name, arr in result.metrics.items():
                if name in self.f["metrics"]:
                    ds = self.f["metrics"][name]
                    ds[sel] = np.asarray(arr)[order]
                    written.append(ds)
            for d, arr in result.spectra.items():
                if "spectra" in self.f and d in self.f["spectra"]:
                    ds = self.f["spectra"][d]
                    ds[sel] = np.asarray(arr)[order]
                    written.append(ds)
            for cell, msg in result.messages.items():
                self.f["cells/message"][int(cell)] = msg
            self.f["tasks/wall_s"][task] = result.wall_s
            self.f["tasks/worker"][task] = result.worker
            for ds in written:  # a chunk HDF5 fails to write is reported here, or nowhere
                ds.flush()
            self.f.flush()
            self.f["cells/status"][sel] = np.asarray(result.status)[order]
            self.f.flush()
        except (OSError, RuntimeError) as exc:
            why = first_line(exc)
            self.broken = (
                f"{self.path}: task {task} could not be written ({why}): the output is left as "
                f"a killed writer's; if its disk is full, free some space; then biafc repair "
                f"{self.path} and run the study again to continue"
            )
            leave_open(self.path)
            raise StudyFileError(self.broken) from None

    def close(self, status: str) -> None:
        """Mark the output ``complete``, ``incomplete`` (interrupted) or ``failed``; close. A
        store that failed a write (:attr:`broken`) leaves the file alone: HDF5 left an output
        it closed after a failed write on a full disk unreadable, even to ``biafc repair``."""
        if self.broken is not None or not self.f.id.valid:
            return
        try:
            self.f.flush()
            self.f.close()
            with open_to_finish(self.path) as f:  # attributes: outside SWMR, after readers
                f.attrs["status"] = status
        except (OSError, RuntimeError) as exc:
            self.broken = not_closed(self.path, exc)
            leave_open(self.path)
            raise StudyFileError(self.broken) from None


def _create_tasks(f: h5py.File, n_tasks: int, cells_per_task: int | None) -> None:
    t = f.create_group("tasks")
    t.create_dataset("wall_s", shape=(n_tasks,), dtype="f8", fillvalue=np.nan)
    t.create_dataset("worker", shape=(n_tasks,), dtype=h5py.string_dtype())
    if cells_per_task is not None:
        t.attrs["cells_per_task"] = cells_per_task


def _regroup_tasks(f: h5py.File, n_tasks: int, cells_per_task: int | None) -> None:
    """``/tasks`` in this run's grouping: as it is when it counts in it (the same
    ``cells_per_task``, or an output without the attribute whose size matches), else moved
    to ``/tasks_earlier/<k>`` and made anew (before SWMR starts: no new objects after)."""
    t = f["tasks"]
    old = t.attrs.get("cells_per_task")
    size = int(t["wall_s"].shape[0])
    if size == n_tasks and (old is None or cells_per_task is None or int(old) == cells_per_task):
        if old is None and cells_per_task is not None:
            t.attrs["cells_per_task"] = cells_per_task
        return
    earlier = f.require_group("tasks_earlier")
    f.move("tasks", f"tasks_earlier/{len(earlier)}")
    _create_tasks(f, n_tasks, cells_per_task)


def _same_model(p: Path, f: h5py.File, model_version: str, accept: bool) -> None:
    """Refuse to continue an output whose cells another model version ran, or record the
    change (``accept``: ``--accept-model-change``)."""
    old = str(f.attrs.get("model_version", "") or "")
    if old == model_version:
        return
    if not accept:
        if not old:
            raise StudyFileError(
                f"{p}: made before study outputs recorded their model version, so its cells may "
                f"come from another DEM kernel than this one ({model_version}); give "
                "--accept-model-change to continue it, recording the change, or choose another "
                "--out"
            )
        raise StudyFileError(
            f"{p}: its cells were run by another model ({old}); this software runs "
            f"{model_version}, and the two would mix; give --accept-model-change to continue "
            "it, recording the change, or choose another --out"
        )
    changes = json.loads(str(f.attrs.get("model_changes_json", "[]")))
    changes.append(
        {
            "from": old or "not recorded",
            "to": model_version,
            "cells_done": int(np.count_nonzero(f["cells/status"][...] != 0)),
            "at_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    )
    f.attrs["model_changes_json"] = json.dumps(changes)
    f.attrs["model_version"] = model_version


def _software() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"biafc-lab {version('biafc-lab')}"
    except PackageNotFoundError:
        return "biafc-lab"


@dataclass
class StudyData:
    """A study output in memory: ``parameters`` name -> [n] (SI), ``units`` name -> unit,
    ``metrics`` name -> [n], ``status [n]``, ``point [n]``, ``messages``, spectra (direction ->
    [n, F] with ``spectrum_freq_Hz``) and the root attributes."""

    path: Path
    attrs: dict[str, Any]
    parameters: dict[str, NDArray[np.float64]]
    metrics: dict[str, NDArray[np.float64]]
    units: dict[str, str]
    status: NDArray[np.int8]
    point: NDArray[np.int64]
    messages: NDArray[Any]
    spectrum_freq_Hz: NDArray[np.float64] | None
    spectra: dict[str, NDArray[np.float32]]
    task_wall_s: NDArray[np.float64]

    @property
    def directions(self) -> list[str]:
        return list(json.loads(str(self.attrs.get("directions", "[]"))))

    @property
    def n_cells(self) -> int:
        return int(self.status.size)


def read_study(path: str | Path, *, spectra: bool = True) -> StudyData:
    """Read a whole study output (figures, tests). Raises :class:`StudyFileError`."""
    from protocols.runfile import RunFileError, open_for_reading

    p = Path(path)
    try:
        with open_for_reading(p) as f:  # also one being written, or left by a killed writer
            return _read_study(p, f, spectra)
    except (OSError, RunFileError) as exc:
        raise _unreadable(p, exc) from None


def read_open_study(path: Path, f: h5py.File, *, spectra: bool = True) -> StudyData:
    """The whole study output ``path`` from ``f``, its handle from
    :func:`protocols.runfile.open_for_reading`, as :func:`read_study`."""
    try:
        return _read_study(path, f, spectra)
    except OSError as exc:
        raise _unreadable(path, exc) from None


def _unreadable(path: Path, exc: BaseException) -> StudyFileError:
    """The one line of an output that does not read: which cells, where their results fail
    their checksum (:mod:`protocols.damaged_cells`), else h5py's first line."""
    from protocols.damaged_cells import damaged_cells, shown

    try:
        damaged = damaged_cells(path)
    except Exception:  # damaged elsewhere too: h5py's own line below
        damaged = []
    if damaged:
        n = sum(b - a for a, b in damaged)
        return DamagedCellsError(
            f"{path}: the results of {n} cell(s) fail their checksum (damaged on disk; the "
            f"other cells are intact): {shown(damaged)}; biafc repair {path} clears them, and "
            "the study run again computes them"
        )
    why = (str(exc).splitlines() or [type(exc).__name__])[0]
    return StudyFileError(f"{path}: cannot read ({why})")


def _read_study(p: Path, f: h5py.File, spectra: bool) -> StudyData:
    if f.attrs.get("format") != FORMAT:
        raise StudyFileError(f"{p}: not a study output")
    attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    pnames = json.loads(str(f["parameters"].attrs["order"]))
    mnames = json.loads(str(f["metrics"].attrs["order"]))
    units = {n: str(f["parameters"][n].attrs.get("unit", "")) for n in pnames}
    units.update({n: str(f["metrics"][n].attrs.get("unit", "")) for n in mnames})
    freq = None
    spec: dict[str, NDArray[np.float32]] = {}
    if spectra and "spectra" in f:
        freq = f["spectra/freq_Hz"][...]
        spec = {d: f["spectra"][d][...] for d in f["spectra"] if d != "freq_Hz"}
    return StudyData(
        path=p,
        attrs=attrs,
        parameters={n: f["parameters"][n][...] for n in pnames},
        metrics={n: f["metrics"][n][...] for n in mnames},
        units=units,
        status=f["cells/status"][...],
        point=f["cells/point"][...],
        messages=f["cells/message"].asstr()[...],
        spectrum_freq_Hz=freq,
        spectra=spec,
        task_wall_s=f["tasks/wall_s"][...],
    )
