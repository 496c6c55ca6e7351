"""The run file (HDF5), format_version 1: its layout, its writer and its reader, in one place.

Every part of biafc-lab that touches a run file (the run engine, ``biafc simulate``, the
simulated bench, the analysis and the GUI) goes through this module, so the layout lives here
and nowhere else. Layout (see the design notes)::

    /                 attrs: format="biafc-run", format_version=1, created, software_version,
                             backend ("sim"|"hardware"|"dem"), status, protocol_yaml, bench_yaml;
                      time stamps (created, started, resumed: the last resume, finished)
                      ISO 8601 in UTC, "2026-11-28T13:58:46+00:00"; run engine, at a resume:
                      resumes_json, a JSON list with one entry per resume (started, the
                      software and host as at creation, seed, and bench_yaml: the bench text
                      it ran with, only where it differs from the root's), and with
                      --accept-bench-change bench_overrides_json, one entry per accepted
                      change (time, differences, bench_yaml)
    /snapshot         attr json: every instrument's snapshot() at start (when the file is
                      created, before any burst is set up or the stage homed)
        armed         (run engine) rows (time, direction, amplitude_index, amplitude, json):
                      the generator's snapshot() each time it was set up for a direction and
                      amplitude (the burst as it read it back: Vpp, offset, sample rate,
                      load) and read_back.vibrometer.range, the decoder range then (its
                      sensitivity and delay are per point, below); a resume adds rows (the
                      first one after it shows what the resume ran with). time: unix s
                      (UTC); amplitude_index: 0-based row of the direction's amplitudes
    /chain            lengths_m [N], onset_Hz [N, B], cutoff_Hz [N, B] (attr axes: row n
                      cylinder n + 1, column b its band b + 1 in rising frequency, onset 0 Hz
                      for the acoustic band; files before 2026-11-28 have no axes attr);
                      attrs diameter_m, f0_N, beta_c
    /scan/<direction> NXdata (signal=velocity, axes=[amplitudes, cylinders, time]);
                      attrs f_center_Hz, cycles and width_s (the burst's Gaussian sigma,
                      s; both always given, one derived from the other), averages
        amplitudes    [A] float64, attr units
        cylinders     [C] int32, 1-based
        time          [S] float64, s from the trigger
        velocity      [A, C, S] float32, m/s, mean over averages; NaN until measured; run
                      engine: attrs decoder_delay_undone_s (s, at the run's start) and
                      decoder_delay_note: the decoder output lags the velocity by its signal
                      delay, undone (shifted earlier, band-limited) before storing
        drive         [A, C, S] float32, V (sim/dem: the applied drive in its own unit, attr units)
                      (velocity and drive: one chunk a point, each with a Fletcher-32 checksum
                      that HDF5 checks at every read; files before 2026-11-27 have none)
        done          [A, C] uint8: 0 pending, 1 measured and flushed, 2 failed (attr codes
                      says so)
        measured_at   [A, C] float64, unix time (NaN until measured)
        fail_reason   [A, C] str: why a failed point failed (its last attempt's error, one
                      line); empty for the others
        sensitivity_m_per_s_per_V  [A, C] float64, m/s per V: the vibrometer sensitivity
                      (its range) each point's volts were scaled by; NaN where not measured
                      or not a vibrometer's (dem)
        decoder_delay_undone_s     [A, C] float64, s: the decoder delay undone in each
                      point (per point: a resume may run on another range); NaN likewise
    /log              (time, level, message) rows, resizable; attrs time_units (s since the
                      unix epoch, UTC) and description
    /simulation       (optional) attrs of the DEM behind the data: integrator, order, dt_s (s),
                      error_estimate_rel (step-doubling estimate of the velocity error, relative
                      L2, worst cylinder; worst run), work_not_in_chain_rel (the fraction
                      of the actuator's input work no longer in the chain at the end:
                      dissipated by the damping, plus the integrator's energy error, which
                      is all of it on an undamped chain; largest magnitude), and for the simulated
                      bench dem_runs_json: a JSON list with one entry per DEM run (direction,
                      kind, amplitude and its units, the same indicators). ``biafc simulate``
                      writes them at creation; the run engine when the file closes (a
                      resume: the earlier sessions' runs, then its own, the worst over all;
                      a killed session's runs were never written, and dem_runs_note then
                      says how many (direction, amplitude) pairs have none listed).

Fields added after the first files (files before 2026-11-28 lack them, and readers take them
as empty, NaN or no rows): ``fail_reason``, ``sensitivity_m_per_s_per_V``,
``decoder_delay_undone_s`` (dataset and velocity attribute), ``/snapshot/armed``, the ``codes``
of ``done``, the attributes of ``/log``, ``started`` in ``resumes_json``. A ``--resume`` of
such a file creates them, empty (NaN) for the points measured before it; the velocity's
decoder-delay attributes stay absent there (the earlier points' delay is not known).

The same file is valid NeXus, so NeXus readers (nexusformat, silx, h5web) open it with axes and
units, without changing the layout above: the root is an ``NXroot`` whose ``default`` is
``scan``; ``/scan`` is the ``NXentry`` (``default``: its first direction; ``start_time``);
every ``/scan/<direction>`` is an ``NXdata`` whose signal (velocity) and axes carry ``units`` and
``long_name``; ``/scan/sample`` (``NXsample``) names the chain and holds ``/chain``'s datasets
(HDF5 hard links: the same data under two names, with units) and ``/scan/instrument``
(``NXinstrument``) holds one group per instrument (its ``snapshot()`` as attribute ``json``;
``NXdetector`` the vibrometer, ``NXpositioner`` the stage). Readers of the biafc layout ignore
the NeXus attributes and groups.

Writing uses SWMR and flushes after every point, so a crash loses at most the point in flight
and a reader can follow a run live. HDF5 forbids changing attributes under SWMR, so the final
``status`` is written when the writer closes (re-opening the file without SWMR), with the run
engine's ``outcome``: the words the run's last line begins with ("complete", "finished with
failed points: ...", "run failed: <reason>", "run aborted: ...", "run UNSAFE (<reason>):
SWITCH OFF BY HAND: ..."), so that a run that failed and one that finished with failed points
(both ``status`` "failed") differ in the file too; a resume removes it until its own close,
and a repair writes its own. Older files have no ``outcome``.
"""

from __future__ import annotations

import json
import os
import socket
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np
from numpy.typing import NDArray

from protocols.damaged_records import bad_points
from protocols.finish_open import not_closed, open_to_finish
from protocols.hdf5probe import HDF5ProbeError, probe_hdf5
from protocols.left_open import leave_open
from protocols.one_line import first_line
from protocols.recover import ClearedView, has_consistency_flags
from protocols.swmr_read import open_swmr

__all__ = [
    "DIRECTIONS",
    "FORMAT",
    "FORMAT_VERSION",
    "ChainInfo",
    "DamagedRecordsError",
    "PointState",
    "RunData",
    "RunFileError",
    "RunFileWriter",
    "ScanData",
    "ScanSpec",
    "now_iso",
    "one_line_errors",
    "open_for_reading",
    "pending_points",
    "read_open_run",
    "read_run",
    "software_version",
    "stored_texts",
]

FORMAT = "biafc-run"
FORMAT_VERSION = 1
DIRECTIONS = ("ltr", "rtl")
Backend = Literal["sim", "hardware", "dem"]
Status = Literal["running", "complete", "aborted", "failed", "unsafe"]
STATUSES = ("running", "complete", "aborted", "failed", "unsafe")


#: what the rows and columns of /chain/onset_Hz and /chain/cutoff_Hz are (their attr ``axes``)
BAND_AXES = (
    "[N, B]: row n is cylinder n + 1 (from the left end), column b its quasi-band b + 1 in "
    "rising frequency (onset_Hz to cutoff_Hz); a band whose onset is 0 Hz is the acoustic band"
)


class PointState:
    """Values of the ``done`` dataset."""

    PENDING = 0
    DONE = 1
    FAILED = 2


#: the meaning of the ``done`` codes, as the dataset's attribute ``codes`` states it
DONE_CODES = "0 not measured, 1 done (measured and flushed), 2 failed (reason in fail_reason)"

#: what the velocity's attribute ``decoder_delay_undone_s`` means
DECODER_DELAY_NOTE = (
    "the vibrometer decoder's output lags the velocity by its signal delay; each record was "
    "shifted earlier by it (band-limited) before storing, so that it lines up with the drive. "
    "decoder_delay_undone_s: the delay at the run's start (s); per point in the dataset "
    "decoder_delay_undone_s beside this one (a resume may run on another range)"
)

#: the per-point float datasets ([A, C], NaN until measured): name -> (units, long_name)
POINT_VALUES = {
    "sensitivity_m_per_s_per_V": (
        "m/s/V",
        "vibrometer sensitivity the point's volts were scaled by (its range)",
    ),
    "decoder_delay_undone_s": ("s", "decoder signal delay undone in the point's velocity"),
}

#: the ``/log`` table's columns and the unit of its time, as its attributes state them
LOG_DESCRIPTION = "one row per event: time, level (debug|info|warning|error), message"
LOG_TIME_UNITS = "s since the unix epoch (UTC)"


class RunFileError(ValueError):
    """The file is not a biafc run file, or not one this version reads."""


class DamagedRecordsError(RunFileError):
    """Records of some points fail their checksum (damaged on disk); the rest of the file
    reads. ``biafc repair`` clears them (:mod:`protocols.damaged_records`)."""


def software_version() -> str:
    """Installed version of biafc-lab (``"unknown"`` when run from a bare checkout)."""
    try:
        return version("biafc-lab")
    except PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class ChainInfo:
    """The model's view of the chain stored in every run file.

    Shapes: ``lengths_m [N]``, ``onset_Hz [N, B]``, ``cutoff_Hz [N, B]``.
    """

    lengths_m: NDArray[np.float64]
    diameter_m: float
    f0_N: float
    beta_c: float
    onset_Hz: NDArray[np.float64]
    cutoff_Hz: NDArray[np.float64]

    @classmethod
    def of_model(cls, chain: Any, bands: Any) -> ChainInfo:
        """The view of a built ``sim_backend.dem.Chain`` and its ``Bands`` (duck-typed: this
        layer does not import the model)."""
        return cls(
            lengths_m=np.asarray(chain.lengths_m, dtype=np.float64),
            diameter_m=float(chain.diameter_m),
            f0_N=float(chain.f0_N),
            beta_c=float(chain.beta_c),
            onset_Hz=np.asarray(bands.onset_Hz, dtype=np.float64),
            cutoff_Hz=np.asarray(bands.cutoff_Hz, dtype=np.float64),
        )


@dataclass(frozen=True)
class ScanSpec:
    """Shape and axes of one direction's scan, fixed when the file is created."""

    direction: str
    amplitudes: NDArray[np.float64]
    amplitude_units: str
    cylinders: NDArray[np.int32]
    time_s: NDArray[np.float64]
    f_center_Hz: float
    cycles: float | None = None
    width_s: float | None = None
    averages: int = 1
    drive_units: str = "V"
    #: the decoder delay (s) undone in the velocity records at the run's start; ``None``: no
    #: vibrometer (the model's velocity), no attribute
    decoder_delay_undone_s: float | None = None


@dataclass
class ScanData:
    """One direction's scan as read. Shapes ``[A]``, ``[C]``, ``[S]``, ``[A, C, S]``, ``[A, C]``."""

    direction: str
    amplitudes: NDArray[np.float64]
    amplitude_units: str
    cylinders: NDArray[np.int32]
    time_s: NDArray[np.float64]
    velocity: NDArray[np.float32]
    drive: NDArray[np.float32]
    drive_units: str
    done: NDArray[np.uint8]
    measured_at: NDArray[np.float64]
    f_center_Hz: float
    cycles: float | None
    width_s: float | None
    averages: int
    #: [A, C] str: why each failed point failed, empty when it did not (or the file is older)
    fail_reason: NDArray[np.object_]
    #: [A, C] the vibrometer sensitivity (m/s per V) and the decoder delay undone (s) of each
    #: point; NaN where not measured, not a vibrometer's, or the file is older
    sensitivity_m_per_s_per_V: NDArray[np.float64]
    decoder_delay_undone_s: NDArray[np.float64]

    @property
    def sample_rate_Hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.time_s)))

    def is_done(self) -> NDArray[np.bool_]:
        return self.done == PointState.DONE


@dataclass
class RunData:
    """A whole run file in memory."""

    path: Path
    attrs: dict[str, Any]
    snapshot: dict[str, Any]
    chain: ChainInfo
    scans: dict[str, ScanData]
    log: list[tuple[float, str, str]] = field(default_factory=list)
    simulation: dict[str, Any] = field(default_factory=dict)
    #: ``/snapshot/armed``: each a dict of time, direction, amplitude_index, amplitude and
    #: snapshot (empty for a file without it)
    armed_snapshots: list[dict[str, Any]] = field(default_factory=list)

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", ""))

    @property
    def backend(self) -> str:
        return str(self.attrs.get("backend", ""))


_LOG_DTYPE = np.dtype(
    [
        ("time", np.float64),
        ("level", h5py.string_dtype("utf-8")),
        ("message", h5py.string_dtype("utf-8")),
    ]
)


_ARMED_DTYPE = np.dtype(
    [
        ("time", np.float64),
        ("direction", h5py.string_dtype("utf-8")),
        ("amplitude_index", np.int32),
        ("amplitude", np.float64),
        ("json", h5py.string_dtype("utf-8")),
    ]
)

ARMED_DESCRIPTION = (
    "the generator's snapshot() (json: generator, as in /snapshot's) each time it was set up "
    "for a direction and amplitude, the burst as it read it back, and the vibrometer's range "
    "then (read_back.vibrometer.range); a resume adds rows. /snapshot's own json is every "
    "instrument's at creation, before any set-up. "
    "amplitude_index: 0-based row of /scan/<direction>/amplitudes"
)


def now_iso() -> str:
    """Now, as every time stamp of a run file is written: ISO 8601 in UTC, to the second
    (``"2026-11-28T13:58:46+00:00"``)."""
    return datetime.now(UTC).isoformat(timespec="seconds")


class RunFileWriter:
    """Creates or re-opens a run file and writes points into it, flushed one by one.

    Use :meth:`create` for a new run and :meth:`open_existing` to resume. Call :meth:`close`
    with the final status; a writer that is never closed (crash, SIGKILL) leaves a readable
    file whose status is still ``"running"`` and whose ``done`` flags tell what was measured.
    """

    def __init__(self, path: Path, handle: h5py.File) -> None:
        self.path = path
        self._f = handle
        self._closed = False
        #: why the file took no more writes (a records write failed), else ``None``: the
        #: writer then leaves the file alone, as a killed writer would (HDF5 crashed the
        #: process closing a file after a failed write on a full disk)
        self.broken: str | None = None

    def _check_usable(self) -> None:
        if self.broken is not None:
            raise RunFileError(self.broken)

    # -- creation -------------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        path: str | Path,
        *,
        backend: Backend,
        chain: ChainInfo,
        scans: Sequence[ScanSpec],
        protocol_yaml: str = "",
        bench_yaml: str = "",
        snapshot: Mapping[str, Any] | None = None,
        simulation: Mapping[str, Any] | None = None,
        extra_attrs: Mapping[str, Any] | None = None,
        swmr: bool = True,
    ) -> RunFileWriter:
        """Create ``path`` (refused if it exists) with every dataset of the layout.

        Velocity and drive start as NaN, ``done`` as 0. ``simulation`` (optional) becomes the
        attributes of ``/simulation``. Creation is atomic: the layout is written under a
        temporary name (``.NAME.PID.part`` beside it) and linked to ``path`` once complete, so a
        crash while creating leaves no half-made file under the run's name.
        """
        path = Path(path)
        if path.exists():
            raise FileExistsError(f"run file {path} exists already (use --resume to continue it)")
        tmp = path.with_name(f".{path.name}.{os.getpid()}.part")
        tmp.unlink(missing_ok=True)
        f = h5py.File(tmp, "w", libver="latest")
        try:
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["created"] = now_iso()
            f.attrs["software_version"] = software_version()
            f.attrs["host"] = socket.gethostname()
            f.attrs["backend"] = backend
            f.attrs["status"] = "running"
            f.attrs["started"] = now_iso()
            f.attrs["protocol_yaml"] = protocol_yaml
            f.attrs["bench_yaml"] = bench_yaml
            for key, value in (extra_attrs or {}).items():
                f.attrs[key] = value
            snap = f.create_group("snapshot")
            snap.attrs["json"] = json.dumps(dict(snapshot or {}), default=str, sort_keys=True)
            g = f.create_group("chain")
            for name, data, units in (
                ("lengths_m", np.asarray(chain.lengths_m, dtype=np.float64), "m"),
                ("onset_Hz", np.atleast_2d(np.asarray(chain.onset_Hz, float)), "Hz"),
                ("cutoff_Hz", np.atleast_2d(np.asarray(chain.cutoff_Hz, float)), "Hz"),
            ):
                ds = g.create_dataset(name, data=data)
                ds.attrs["units"] = units
                if name != "lengths_m":
                    ds.attrs["axes"] = BAND_AXES
            g.attrs["diameter_m"] = float(chain.diameter_m)
            g.attrs["f0_N"] = float(chain.f0_N)
            g.attrs["beta_c"] = float(chain.beta_c)
            scan_root = f.create_group("scan")
            for spec in scans:
                cls._create_scan(scan_root, spec)
            _nexus_entry(f, scans, dict(snapshot or {}))
            f.create_dataset("log", shape=(0,), maxshape=(None,), dtype=_LOG_DTYPE, chunks=(64,))
            _require_file_fields(f)
            if simulation:
                sim = f.create_group("simulation")
                for key, value in simulation.items():
                    sim.attrs[key] = value
            f.flush()
            _publish(tmp, path)
        except BaseException:
            f.close()
            tmp.unlink(missing_ok=True)
            raise
        try:
            if swmr:
                f.swmr_mode = True
        except BaseException:
            f.close()
            raise
        return cls(path, f)

    @staticmethod
    def _create_scan(root: h5py.Group, spec: ScanSpec) -> None:
        if spec.direction not in DIRECTIONS:
            raise ValueError(f"direction must be one of {DIRECTIONS}, got {spec.direction!r}")
        A, C, S = len(spec.amplitudes), len(spec.cylinders), len(spec.time_s)
        g = root.create_group(spec.direction)
        g.attrs["NX_class"] = "NXdata"
        g.attrs["signal"] = "velocity"
        g.attrs["axes"] = ["amplitudes", "cylinders", "time"]
        for k, name in enumerate(("amplitudes", "cylinders", "time")):
            g.attrs[f"{name}_indices"] = k
        g.attrs["auxiliary_signals"] = ["drive"]
        g.attrs["f_center_Hz"] = float(spec.f_center_Hz)
        cycles, width_s = _burst_cycles_and_width(spec)
        g.attrs["cycles"] = cycles
        g.attrs["width_s"] = width_s
        g.attrs["averages"] = int(spec.averages)
        amp = g.create_dataset("amplitudes", data=np.asarray(spec.amplitudes, dtype=np.float64))
        amp.attrs["units"] = spec.amplitude_units
        amp.attrs["long_name"] = _AMPLITUDE_NAMES.get(spec.amplitude_units, "drive amplitude")
        cyl = g.create_dataset("cylinders", data=np.asarray(spec.cylinders, dtype=np.int32))
        cyl.attrs["units"] = ""  # a number: dimensionless
        cyl.attrs["long_name"] = "cylinder (1-based, from the short end)"
        t = g.create_dataset("time", data=np.asarray(spec.time_s, dtype=np.float64))
        t.attrs["units"] = "s"
        t.attrs["long_name"] = "time from the trigger"
        records = (
            ("velocity", "m/s", "velocity (mean over averages)"),
            ("drive", spec.drive_units, "drive reference"),
        )
        for name, units, long_name in records:
            # one chunk a point, each with its Fletcher-32 checksum: HDF5 checks it at every
            # read, so bytes damaged on disk inside a point's records are refused, not read
            ds = g.create_dataset(name, shape=(A, C, S), dtype=np.float32, fillvalue=np.nan,
                                  chunks=(1, 1, S), fletcher32=True)  # fmt: skip
            ds.attrs["units"] = units
            ds.attrs["long_name"] = long_name
        if spec.decoder_delay_undone_s is not None:
            g["velocity"].attrs["decoder_delay_undone_s"] = float(spec.decoder_delay_undone_s)
            g["velocity"].attrs["decoder_delay_note"] = DECODER_DELAY_NOTE
        g.create_dataset("done", shape=(A, C), dtype=np.uint8, fillvalue=0)
        m = g.create_dataset("measured_at", shape=(A, C), dtype=np.float64, fillvalue=np.nan)
        m.attrs["units"] = "s since the unix epoch"
        _require_point_fields(g)

    @classmethod
    def open_existing(
        cls,
        path: str | Path,
        *,
        swmr: bool = True,
        extra_attrs: Mapping[str, Any] | None = None,
        resumed: bool = True,
    ) -> RunFileWriter:
        """Re-open an interrupted run file to append points (``--resume``); ``extra_attrs``
        are set on the root before SWMR starts. ``resumed``: stamp the root's ``resumed``
        time (not for a repair, which measures nothing) and give a file written before them
        the fields added to the layout since (empty: nothing is known of its earlier points)."""
        path = Path(path)
        _check_format(path)
        f = h5py.File(path, "r+", libver="latest")
        try:  # what can fail first, the status last: a failed re-open leaves it as it was
            if resumed:
                _require_file_fields(f)
                for g in f["scan"].values():
                    if isinstance(g, h5py.Group) and "done" in g:
                        _require_point_fields(g)
            for key, value in (extra_attrs or {}).items():
                f.attrs[key] = value
            f.attrs["status"] = "running"
            if "outcome" in f.attrs:  # the earlier session's: this one's is written at its close
                del f.attrs["outcome"]
            if resumed:
                f.attrs["resumed"] = now_iso()
            f.flush()
            if swmr:
                f.swmr_mode = True
        except BaseException:
            f.close()  # not left open in the process (a reviewer)
            raise
        return cls(path, f)

    # -- writing --------------------------------------------------------------------------
    def write_point(
        self,
        direction: str,
        amplitude_index: int,
        cylinder_index: int,
        velocity: NDArray[np.floating[Any]],
        drive: NDArray[np.floating[Any]],
        measured_at: float | None = None,
        *,
        sensitivity_m_per_s_per_V: float | None = None,
        decoder_delay_undone_s: float | None = None,
    ) -> None:
        """Store one point (0-based indices), mark it done and flush. Shapes ``[S]``.
        ``sensitivity_m_per_s_per_V`` and ``decoder_delay_undone_s``: what the velocity was
        made with (a vibrometer's), kept per point where given.

        The records are flushed before the point is marked done: HDF5 writes a chunk when it
        leaves the chunk cache, and a write that fails there (a full disk) is reported nowhere
        a caller could see. A records write that fails raises :class:`RunFileError` (one line)
        and the point stays pending."""
        self._check_usable()
        g = self._f["scan"][direction]
        try:
            for name, values in (("velocity", velocity), ("drive", drive)):
                ds = g[name]
                ds[amplitude_index, cylinder_index, :] = np.asarray(values, np.float32)
                ds.flush()
        except (OSError, RuntimeError) as exc:
            why = first_line(exc)
            self.broken = (
                f"{self.path}: the records of point {direction} amplitude #{amplitude_index + 1} "
                f"cylinder #{cylinder_index + 1} could not be written ({why}): the file is left "
                f"as a killed writer's; if its disk is full, free some space; then "
                f"run_protocol --resume {self.path} (or biafc repair {self.path} to read it as it "
                "is)"
            )
            leave_open(self.path)
            raise RunFileError(self.broken) from None
        g["measured_at"][amplitude_index, cylinder_index] = (
            time.time() if measured_at is None else measured_at
        )
        for name, value in (
            ("sensitivity_m_per_s_per_V", sensitivity_m_per_s_per_V),
            ("decoder_delay_undone_s", decoder_delay_undone_s),
        ):
            if value is not None and name in g:
                g[name][amplitude_index, cylinder_index] = value
        done = g["done"]
        if done[amplitude_index, cylinder_index] == PointState.FAILED and "fail_reason" in g:
            g["fail_reason"][amplitude_index, cylinder_index] = ""  # measured now: no failure
        done[amplitude_index, cylinder_index] = PointState.DONE
        self._f.flush()

    def clear_point(self, direction: str, amplitude_index: int, cylinder_index: int) -> None:
        """Empty one point (0-based indices): its records NaN (written whole, so a chunk that
        failed its checksum is replaced, not read), ``done`` pending, ``measured_at`` NaN;
        flushed. For records damaged on disk (:mod:`protocols.damaged_records`)."""
        self._check_usable()
        g = self._f["scan"][direction]
        for name in ("velocity", "drive"):
            ds = g[name]
            ds[amplitude_index, cylinder_index, :] = np.full(ds.shape[2], np.nan, np.float32)
            ds.flush()
        g["measured_at"][amplitude_index, cylinder_index] = np.nan
        for name in POINT_VALUES:
            if name in g:
                g[name][amplitude_index, cylinder_index] = np.nan
        g["done"][amplitude_index, cylinder_index] = PointState.PENDING
        if "fail_reason" in g:
            g["fail_reason"][amplitude_index, cylinder_index] = ""
        self._f.flush()

    def mark_failed(
        self, direction: str, amplitude_index: int, cylinder_index: int, reason: str = ""
    ) -> None:
        """Mark a point that failed after its retries (``done`` = 2), keep ``reason`` (one
        line: its last attempt's error) in ``fail_reason`` where the file has it, and flush."""
        self._check_usable()
        g = self._f["scan"][direction]
        if "fail_reason" in g:
            line = (reason.splitlines() or [""])[0]
            g["fail_reason"][amplitude_index, cylinder_index] = line[:1000]
        g["done"][amplitude_index, cylinder_index] = PointState.FAILED
        self._f.flush()

    def add_snapshot(
        self,
        direction: str,
        amplitude_index: int,
        amplitude: float,
        snapshot: Mapping[str, Any],
        when: float | None = None,
    ) -> None:
        """Append a row to ``/snapshot/armed`` (the instruments as set up for ``direction``
        and amplitude ``amplitude_index``, 0-based) and flush; nothing in a file without it."""
        self._check_usable()
        if "armed" not in self._f["snapshot"]:
            return
        ds = self._f["snapshot"]["armed"]
        n = ds.shape[0]
        ds.resize((n + 1,))
        row = np.zeros(1, dtype=_ARMED_DTYPE)
        text = json.dumps(dict(snapshot), default=str, sort_keys=True)
        t = time.time() if when is None else when
        row[0] = (t, direction, amplitude_index, amplitude, text)
        ds[n] = row[0]
        self._f.flush()

    def attrs_json(self, name: str) -> Any:
        """A root attribute holding JSON, decoded (``None`` when absent)."""
        v = self._f.attrs.get(name)
        if v is None:
            return None
        return json.loads(v.decode() if isinstance(v, bytes) else str(v))

    def earlier_dem_runs(self) -> list[dict[str, Any]]:
        """The DEM runs an earlier session of this file recorded (``/simulation`` attribute
        ``dem_runs_json``; empty when none): a resume keeps them beside its own."""
        if "simulation" not in self._f:
            return []
        v = self._f["simulation"].attrs.get("dem_runs_json")
        if v is None:
            return []
        return list(json.loads(v.decode() if isinstance(v, bytes) else str(v)))

    def done_mask(self, direction: str) -> NDArray[np.uint8]:
        """The ``done`` array ``[A, C]`` of one direction."""
        return np.asarray(self._f["scan"][direction]["done"][...])

    def log(self, level: str, message: str, when: float | None = None) -> None:
        """Append a row to ``/log`` and flush."""
        self._check_usable()
        ds = self._f["log"]
        n = ds.shape[0]
        ds.resize((n + 1,))
        row = np.zeros(1, dtype=_LOG_DTYPE)
        row[0] = (time.time() if when is None else when, level, message)
        ds[n] = row[0]
        self._f.flush()

    def close(
        self,
        status: Status,
        *,
        simulation: Mapping[str, Any] | None = None,
        stamp: str = "finished",
        outcome: str | None = None,
    ) -> None:
        """Close, writing the final ``status`` (and the time, as root attribute ``stamp``:
        ``finished``, or ``repaired`` for a repair; and ``outcome`` when given, see the module
        docstring) as root attributes and ``simulation``
        (optional) as attributes of ``/simulation`` (created if absent; SWMR forbids new
        attributes while writing, so they are set here)."""
        if self._closed:
            return
        self._check_usable()
        if status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
        try:
            self._f.flush()
            self._f.close()
            self._closed = True
            with open_to_finish(self.path) as f:  # waits for readers following the run
                f.attrs["status"] = status
                f.attrs[stamp] = now_iso()
                if outcome is not None:
                    f.attrs["outcome"] = outcome
                if simulation:
                    sim = f.require_group("simulation")
                    for key, value in simulation.items():
                        sim.attrs[key] = value
        except (OSError, RuntimeError) as exc:
            self.broken = not_closed(self.path, exc)
            leave_open(self.path)
            raise RunFileError(self.broken) from None

    @property
    def closed(self) -> bool:
        return self._closed


@contextmanager
def open_for_reading(path: str | Path) -> Iterator[h5py.File]:
    """Open a run file read-only: through SWMR (also one being written), or, for a file whose
    writer was killed outside SWMR (while closing), through a view with the consistency
    flags cleared. The file is never changed. A path that is no whole HDF5 file (a folder,
    empty, no signature, truncated) is a :class:`RunFileError` (one line) before h5py sees it.

    SWMR is used only for a file a writer holds (consistency flags set): HDF5's SWMR reader
    retries a metadata read that fails its checksum (right while a writer flushes), by default
    for ever on a damaged file, while a plain read fails at once; :func:`open_swmr` bounds the
    retry to about 0.3 s. A closed file is read without HDF5's file lock, so a reader never
    stops a writer from resuming it."""
    try:
        header = probe_hdf5(path)
    except HDF5ProbeError as exc:
        raise RunFileError(str(exc)) from None
    stale = header.end is not None and header.end < header.size
    if header.flags == 0 and not stale:
        with h5py.File(path, "r", locking=False) as g:
            yield g
        return
    if header.flags == 0:  # flags cleared (h5clear -s) over bytes a killed writer flushed
        with ClearedView(path) as raw, h5py.File(raw, "r") as g:
            yield g
        return
    try:
        f = open_swmr(path)
    except OSError:
        if not Path(path).is_file() or not has_consistency_flags(path):
            raise
        with ClearedView(path) as raw, h5py.File(raw, "r") as g:
            yield g
        return
    with f:
        yield f


def pending_points(path: str | Path) -> int:
    """Points of run file ``path`` not measured yet (pending or failed), from its ``done``
    arrays alone (no records are read)."""
    with open_for_reading(path) as f:
        scans = f["scan"] if "scan" in f else {}
        return sum(
            int(np.sum(scans[d]["done"][...] != PointState.DONE)) for d in DIRECTIONS if d in scans
        )


def _publish(tmp: Path, path: Path) -> None:
    """Give the finished file ``tmp`` its name ``path``, never replacing an existing file."""
    try:
        os.link(tmp, path)  # fails if path exists: no race with another writer
    except FileExistsError:
        raise FileExistsError(
            f"run file {path} exists already (use --resume to continue it)"
        ) from None
    except OSError:  # a file system without hard links
        if path.exists():
            raise FileExistsError(f"run file {path} exists already") from None
        os.rename(tmp, path)
        return
    tmp.unlink()


_AMPLITUDE_NAMES = {
    "V": "generator amplitude (peak to peak)",
    "m": "actuator displacement amplitude",
    "N": "actuator force amplitude",
}

#: NeXus base class of each instrument's group under /scan/instrument (others: NXcollection)
_INSTRUMENT_CLASSES = {"vibrometer": "NXdetector", "stage": "NXpositioner"}


def _burst_cycles_and_width(spec: ScanSpec) -> tuple[float, float]:
    """The burst's length in carrier cycles and its Gaussian sigma (s), whichever was given;
    NaN for both when neither was."""
    from instruments.burst import Burst

    if spec.cycles is None and spec.width_s is None:
        return float("nan"), float("nan")
    b = Burst(spec.f_center_Hz, cycles=spec.cycles, width_s=None if spec.cycles else spec.width_s)
    return b.duration_s * b.f_center_Hz, b.sigma_s


def _require_point_fields(g: h5py.Group) -> None:
    """The per-point fields of scan ``g`` added to the layout after its first files, created
    where absent (a file re-opened to resume): ``fail_reason``, the per-point values
    (:data:`POINT_VALUES`) and the ``codes`` of ``done``."""
    A, C = g["done"].shape
    g["done"].attrs["codes"] = DONE_CODES
    for name, (units, long_name) in POINT_VALUES.items():
        if name not in g:
            ds = g.create_dataset(name, shape=(A, C), dtype=np.float64, fillvalue=np.nan)
            ds.attrs["units"] = units
            ds.attrs["long_name"] = long_name
    if "fail_reason" not in g:
        r = g.create_dataset("fail_reason", shape=(A, C), dtype=h5py.string_dtype("utf-8"))
        r.attrs["long_name"] = "why the point failed (its last attempt's error); empty if not"


def _require_file_fields(f: h5py.File) -> None:
    """The file-wide fields added to the layout after its first files, set where absent:
    the ``/log`` table's description and time unit, the ``/snapshot/armed`` table."""
    if "log" in f:
        f["log"].attrs["description"] = LOG_DESCRIPTION
        f["log"].attrs["time_units"] = LOG_TIME_UNITS
    snap = f.require_group("snapshot")
    if "armed" not in snap:
        ds = snap.create_dataset(
            "armed", shape=(0,), maxshape=(None,), dtype=_ARMED_DTYPE, chunks=(16,)
        )
        ds.attrs["description"] = ARMED_DESCRIPTION
        ds.attrs["time_units"] = LOG_TIME_UNITS


def _nexus_entry(f: h5py.File, scans: Sequence[ScanSpec], snapshot: dict[str, Any]) -> None:
    """The NeXus view of a run file being created (see the module docstring): NXroot with
    ``/scan`` its NXentry, ``/scan/sample`` (``/chain``'s datasets), ``/scan/instrument``."""
    f.attrs["NX_class"] = "NXroot"
    f.attrs["default"] = "scan"
    f.attrs["file_time"] = f.attrs["created"]
    f.attrs["creator"] = f"biafc-lab {f.attrs['software_version']}"
    entry = f["scan"]
    entry.attrs["NX_class"] = "NXentry"
    if scans:
        entry.attrs["default"] = scans[0].direction
    entry.create_dataset("start_time", data=str(f.attrs["created"]))
    sample = entry.create_group("sample")
    sample.attrs["NX_class"] = "NXsample"
    sample.create_dataset("name", data=f"woodpile chain of {len(f['chain/lengths_m'])} cylinders")
    for name in ("lengths_m", "onset_Hz", "cutoff_Hz"):
        sample[name] = f["chain"][name]  # hard links: one dataset, two names
    for key, value in f["chain"].attrs.items():
        sample.attrs[key] = value
    inst = entry.create_group("instrument")
    inst.attrs["NX_class"] = "NXinstrument"
    for name, snap in sorted(snapshot.items()):
        if not isinstance(snap, dict) or name not in ("generator", "vibrometer", "stage",
                                                      "digitiser"):  # fmt: skip
            continue
        g = inst.create_group(name)
        g.attrs["NX_class"] = _INSTRUMENT_CLASSES.get(name, "NXcollection")
        g.create_dataset("name", data=name)
        g.attrs["json"] = json.dumps(snap, default=str, sort_keys=True)


def _check_format(path: Path) -> None:
    if not path.exists():
        raise FileNotFoundError(f"run file {path} does not exist")
    try:
        with open_for_reading(path) as f:
            _check_open_format(path, f)
    except (OSError, RuntimeError, KeyError) as exc:
        raise RunFileError(_damaged(path, exc)) from None


def _check_open_format(path: Path, f: h5py.File) -> None:
    """Refuse (:class:`RunFileError`) the open file ``f`` unless it is a run file of
    :data:`FORMAT_VERSION`; h5py's errors reading its attributes pass."""
    fmt = f.attrs.get("format")
    ver = f.attrs.get("format_version")
    if fmt != FORMAT:
        what = "it is another HDF5 file" if fmt is None else f"its format attribute is {fmt!r}"
        raise RunFileError(f"{path} is not a biafc run file ({what})")
    if int(ver) != FORMAT_VERSION:
        raise RunFileError(f"{path} has format_version {ver}; this software reads {FORMAT_VERSION}")


def _attr_dict(obj: h5py.HLObject) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in obj.attrs.items():
        if isinstance(value, bytes):
            value = value.decode()
        elif isinstance(value, np.generic):
            value = value.item()
        out[key] = value
    return out


def _opt(value: Any) -> float | None:
    v = float(value)
    return None if np.isnan(v) else v


def stored_texts(path: str | Path) -> tuple[str, str]:
    """``(protocol_yaml, bench_yaml)``: the texts a run file was started with."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"run file {path} does not exist")
    try:
        with open_for_reading(path) as f:  # one open: a damaged file waits its grace once
            _check_open_format(path, f)
            texts = [f.attrs.get(k, "") for k in ("protocol_yaml", "bench_yaml")]
    except (OSError, RuntimeError, KeyError) as exc:
        raise RunFileError(_damaged(path, exc)) from None
    p, b = (t.decode() if isinstance(t, bytes) else str(t) for t in texts)
    return p, b


def read_run(path: str | Path) -> RunData:
    """Read a whole run file (also one still being written, through SWMR), opening it once. A
    missing file is a :class:`FileNotFoundError`; a file that is no run file, or one damaged
    inside, is a :class:`RunFileError` (one line)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"run file {path} does not exist")
    with one_line_errors(path):
        with open_for_reading(path) as f:
            return read_open_run(path, f)


@contextmanager
def one_line_errors(path: Path, passing: tuple[type[Exception], ...] = ()) -> Iterator[None]:
    """h5py's errors of a file damaged inside (raised while opening or reading ``path``)
    become a :class:`RunFileError` naming it (one line); a ``RunFileError``, and the one-line
    errors of the classes in ``passing``, pass as they are."""
    try:
        yield
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        if isinstance(exc, (RunFileError, *passing)):
            raise
        raise RunFileError(_damaged(path, exc)) from None


def read_open_run(path: Path, f: h5py.File) -> RunData:
    """The whole run file ``path`` from ``f``, its handle from :func:`open_for_reading`: the
    format checked (:class:`RunFileError`), then every dataset read; h5py's errors of a
    damaged file pass (:func:`one_line_errors` makes them one line)."""
    _check_open_format(path, f)
    return _read_run(path, f)


def _damaged(path: Path, exc: BaseException) -> str:
    why = first_line(exc)
    return f"{path}: damaged HDF5 file, cannot be read ({why})"


def _read_records(path: Path, direction: str, g: h5py.Group, name: str) -> np.ndarray:
    """The records ``name`` ([A, C, S]) of scan ``g``. A measured point whose chunk fails its
    Fletcher-32 checksum (bytes damaged on disk; files written since 2026-11-27 carry one a
    point) is refused in one line naming the file and the points, found by reading them one by
    one. A point not measured (pending or failed) holds no measurement: its damaged chunk (a
    write a full disk cut short) reads as not measured, NaN; it refused the whole file, even to
    biafc repair, which had cleared the flags that hid it."""
    ds = g[name]
    try:
        return np.asarray(ds[...])
    except OSError as exc:
        if not ds.fletcher32:
            raise  # no checksums in this file: its damage (one_line_errors)
        error = exc
    damaged = bad_points(ds)
    if not damaged:
        raise error  # every point reads alone: some other damage (one_line_errors)
    done = g["done"][...]
    measured = [(a, c) for a, c in damaged if done[a, c] == PointState.DONE]
    if not measured:
        out = np.full(ds.shape, np.nan, dtype=ds.dtype)
        for a in range(ds.shape[0]):
            for c in range(ds.shape[1]):
                if (a, c) not in damaged:
                    out[a, c] = ds[a, c]
        return out
    amps, cyls = g["amplitudes"][...], g["cylinders"][...]
    units = str(g["amplitudes"].attrs.get("units", ""))
    bad = [f"amplitude #{a + 1} ({amps[a]:g} {units}) cylinder {int(cyls[c])}" for a, c in measured]
    listed = "; ".join(bad[:4]) + (f"; and {len(bad) - 4} more" if len(bad) > 4 else "")
    raise DamagedRecordsError(
        f"{path}: {name} records of {len(bad)} {direction} point(s) fail their checksum "
        f"(damaged on disk; the other points are intact): {listed}; biafc repair {path} "
        "clears them, and run_protocol --resume then measures them again"
    )


def _point_values(g: h5py.Group, name: str) -> NDArray[np.float64]:
    """The per-point float dataset ``name`` of scan ``g`` ([A, C]), or NaN where the file has
    none (written before it was in the layout)."""
    if name in g:
        if g.file.swmr_mode:
            g[name].refresh()
        return np.asarray(g[name][...], dtype=np.float64)
    return np.full(g["done"].shape, np.nan)


def _strings(g: h5py.Group, name: str) -> NDArray[np.object_]:
    """The string dataset ``name`` of scan ``g`` ([A, C] of str), or empty strings where the
    file has none (written before it was in the layout)."""
    if name in g:
        if g.file.swmr_mode:
            g[name].refresh()
        return np.asarray(g[name].asstr()[...], dtype=object)
    return np.full(g["done"].shape, "", dtype=object)


def _read_run(path: Path, f: h5py.File) -> RunData:
    attrs = _attr_dict(f)
    snapshot = json.loads(f["snapshot"].attrs.get("json", "{}"))
    c = f["chain"]
    chain = ChainInfo(
        lengths_m=c["lengths_m"][...],
        diameter_m=float(c.attrs["diameter_m"]),
        f0_N=float(c.attrs["f0_N"]),
        beta_c=float(c.attrs["beta_c"]),
        onset_Hz=c["onset_Hz"][...],
        cutoff_Hz=c["cutoff_Hz"][...],
    )
    scans: dict[str, ScanData] = {}
    for direction in DIRECTIONS:
        if direction not in f["scan"]:
            continue
        g = f["scan"][direction]
        if f.swmr_mode:
            for name in ("velocity", "drive", "done", "measured_at"):
                g[name].refresh()
        scans[direction] = ScanData(
            direction=direction,
            amplitudes=g["amplitudes"][...],
            amplitude_units=str(g["amplitudes"].attrs.get("units", "")),
            cylinders=g["cylinders"][...],
            time_s=g["time"][...],
            velocity=_read_records(path, direction, g, "velocity"),
            drive=_read_records(path, direction, g, "drive"),
            drive_units=str(g["drive"].attrs.get("units", "")),
            done=g["done"][...],
            measured_at=g["measured_at"][...],
            f_center_Hz=float(g.attrs["f_center_Hz"]),
            cycles=_opt(g.attrs.get("cycles", np.nan)),
            width_s=_opt(g.attrs.get("width_s", np.nan)),
            averages=int(g.attrs.get("averages", 1)),
            fail_reason=_strings(g, "fail_reason"),
            sensitivity_m_per_s_per_V=_point_values(g, "sensitivity_m_per_s_per_V"),
            decoder_delay_undone_s=_point_values(g, "decoder_delay_undone_s"),
        )
    log_ds = f["log"]
    if f.swmr_mode:
        log_ds.refresh()
    log = [
        (
            float(r["time"]),
            r["level"].decode() if isinstance(r["level"], bytes) else str(r["level"]),
            r["message"].decode() if isinstance(r["message"], bytes) else str(r["message"]),
        )
        for r in log_ds[...]
    ]
    simulation = _attr_dict(f["simulation"]) if "simulation" in f else {}
    return RunData(path, attrs, snapshot, chain, scans, log, simulation, _armed(f))


def _armed(f: h5py.File) -> list[dict[str, Any]]:
    """The rows of ``/snapshot/armed`` (none in a file without it)."""
    if "armed" not in f["snapshot"]:
        return []
    ds = f["snapshot"]["armed"]
    if f.swmr_mode:
        ds.refresh()

    def text(v: Any) -> str:
        return v.decode() if isinstance(v, bytes) else str(v)

    return [
        {
            "time": float(r["time"]),
            "direction": text(r["direction"]),
            "amplitude_index": int(r["amplitude_index"]),
            "amplitude": float(r["amplitude"]),
            "snapshot": json.loads(text(r["json"])),
        }
        for r in ds[...]
    ]
