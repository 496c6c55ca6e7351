"""The run engine: one state machine that runs a protocol on a bench and writes a run file.

States: idle -> running <-> paused -> complete | aborted | failed. :meth:`RunEngine.pause`,
:meth:`RunEngine.resume` and :meth:`RunEngine.abort` are thread-safe and may be called from any
thread (a GUI, a signal handler). Pause and abort act at the next point boundary; abort also
interrupts waits (settling, pause). Whatever ends the run (completion, abort, an instrument
fault, an exception, SIGINT/SIGTERM through the CLI), every instrument is put in its safe state
(generator outputs off, stage stopped) and the outcome is logged in the file.

Per point: move the stage, settle, check the vibrometer signal level, then ``averages`` times:
arm the digitiser, trigger the generator, read, check (NaN, clipping; a trigger timeout raises).
A failed attempt is retried up to ``retries`` times; a point that still fails is marked FAILED
and the run continues or stops per ``on_point_failure``. Velocity is stored in m/s (volts times
the vibrometer's sensitivity), shifted by the decoder's signal delay so it lines up with the
drive.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from daq.engine.decoder_delay import tail_samples, undo_decoder_delay
from daq.engine.events import EventBus, EventKind, RunEvent, RunState, Subscriber
from daq.engine.instruments import BenchInstruments
from daq.engine.keep_awake import cannot_line, keep_awake
from daq.engine.outcome import outcome_text
from daq.engine.plan import Plan, Point, make_plan, points_left
from daq.store import create_run, resume_run
from daq.store.disk_space import DiskFull, room_for_a_point
from instruments.errors import InstrumentError, InstrumentTimeout, SignalLostError
from instruments.interfaces import AcquisitionConfig, BurstConfig
from protocols.bench import BenchFile
from protocols.runfile import PointState, RunFileError, RunFileWriter, ScanSpec
from protocols.schema import ProtocolFile

__all__ = ["DeadInstrumentError", "PointCheckError", "RequestRefused", "RunEngine", "RunResult"]

_LOGGER = logging.getLogger("biafc.run")
_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING,
           "error": logging.ERROR}  # fmt: skip

#: a record is "clipped" when |V| reaches this fraction of the input range
CLIP_FRACTION = 0.995

#: how the reason of a run that went through every point but had failures begins
_POINTS_FAILED = "finished with failed points:"


class PointCheckError(InstrumentError):
    """A record failed its checks (NaN, clipping, low signal): the point is retried."""


class _Aborted(Exception):
    pass


def _held_text(snapshot: dict[str, Any], channel: int) -> str:
    """``", read back 1 Vpp, offset 0 V, 999889.5 Sa/s, load INF, trigger BUS"``: what the
    generator's channel reported holding after configuration (its snapshot's ``read_back``),
    for the run's log; empty when the generator reports none."""
    held = snapshot.get("channels", {}).get(str(channel), {}).get("read_back")
    if not isinstance(held, dict):
        return ""
    try:
        return (
            f", read back {held['amplitude_Vpp']:.6g} {held['amplitude_unit']}, offset "
            f"{held['offset_V']:.6g} V, {held['sample_rate_Hz']:.10g} Sa/s, load "
            f"{held['load_ohm']}, trigger {held['trigger_source']}"
        )
    except (KeyError, TypeError, ValueError):
        return ""


def _homing_time(stage: Any) -> str:
    """``" (at most 2 min 30 s)"``: the longest homing the stage reports
    (``home_time_s``: the whole travel at its homing speed), or "" when it reports none."""
    ask = getattr(stage, "home_time_s", None)
    try:
        longest = ask() if callable(ask) else None
    except InstrumentError:
        return ""
    if longest is None or not longest > 0:
        return ""
    from daq.progress import format_minutes

    return f" (at most {format_minutes(longest)})"


def _jsonable(obj: Any) -> Any:
    """A JSON-ready copy of a settings object (dataclasses, pydantic models, arrays)."""
    import dataclasses

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if hasattr(obj, "model_dump"):
        return _jsonable(obj.model_dump())
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    return str(obj)


class DeadInstrumentError(InstrumentError):
    """An instrument stopped answering (its own query timed out): the run stops at once
    instead of spending every retry of every point on timeouts."""


class RequestRefused(Exception):
    """The request is refused before anything moved (file in use, resume refused); one line."""


@dataclass(frozen=True)
class RunResult:
    """How a run ended.

    ``status``: "complete" | "aborted" | "failed" | "unsafe" | "refused". ``n_done``: points
    measured in the file (of ``n_points``), ``n_measured_now`` of them by this process,
    ``n_already`` found in the file at a resume; ``n_failed``: points marked failed now.
    ``unconfirmed``: what could not be confirmed safe (status "unsafe"), each naming the
    instrument; ``safe_state_s``: seconds from the end request (abort, fault, last point) to
    the confirmed safe state. ``points_failed_only``: the run went through every point but
    some failed (exit status 4; ``--resume`` re-measures them). ``file_written``: the run
    file was made (or, ``resumed``, opened to continue); False where the run ended before
    (an abort or a failure at its start), so that no line names a file that does not exist.
    """

    status: str
    reason: str
    path: Path
    n_done: int
    n_failed: int
    wall_s: float
    n_points: int = 0
    n_measured_now: int = 0
    n_already: int = 0
    unconfirmed: tuple[str, ...] = ()
    safe_state_s: float | None = None
    points_failed_only: bool = False
    file_written: bool = True
    resumed: bool = False


class RunEngine:
    """Runs one protocol on one bench into one run file.

    Parameters
    ----------
    protocol, bench:
        The validated protocol and bench files (their texts go into the file).
    instruments:
        The assembled bench (:func:`daq.connect.connect_bench`, or fakes in tests).
    out_path:
        The run file to create, or (``resume=True``) the interrupted one to continue.
    resume:
        Continue ``out_path``: verify the protocol, skip points already done.
    seed:
        Recorded in the file (the simulated bench's noise seed).

    Use :meth:`subscribe` for events, :meth:`run` (blocking) or :meth:`start` (a thread), and
    :meth:`pause`, :meth:`resume`, :meth:`abort` from any thread.
    """

    def __init__(
        self,
        protocol: ProtocolFile,
        bench: BenchFile,
        instruments: BenchInstruments,
        out_path: str | Path,
        *,
        resume: bool = False,
        seed: int | None = None,
        accept_bench_change: bool = False,
        on_file_locked: Callable[[], None] | None = None,
    ) -> None:
        """``on_file_locked``: called once the run file is this process's (its lock taken),
        before anything is written to it; ``run_protocol`` opens its log file then."""
        self.on_file_locked = on_file_locked
        self.protocol_file = protocol
        self.bench_file = bench
        self.instruments = instruments
        self.out_path = Path(out_path)
        self.resume_mode = resume
        self.seed = seed
        self.accept_bench_change = accept_bench_change
        self.plan: Plan = make_plan(protocol, bench)
        self._bus = EventBus()
        self._lock = threading.RLock()
        self._state = RunState.IDLE
        self._abort = threading.Event()
        self._abort_reason = ""
        self._abort_t: float | None = None  # monotonic time of the first abort request
        self._running = threading.Event()  # set while not paused
        self._running.set()
        self._pause_at_start = False  # paused before the run's thread began (pause)
        self._thread: threading.Thread | None = None
        self._writer: RunFileWriter | None = None
        self._tail = 0  # samples read past each record's window (_configure_digitiser)
        self._delay_s: float | None = None  # the decoder's delay (_configure_digitiser)
        self.result: RunResult | None = None
        #: True once the run is putting the bench in its safe state and closing the file
        self.ending = False
        self._file_lock: Any = None

    # -- subscription and controls (thread-safe) -------------------------------------------
    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call ``callback(RunEvent)`` for every event; returns an unsubscribe function."""
        return self._bus.subscribe(callback)

    @property
    def state(self) -> RunState:
        with self._lock:
            return self._state

    def pause(self) -> None:
        """Pause at the next point boundary (no effect once the run has ended). Asked before the
        run's thread has begun (the gap after :meth:`start`), the run begins paused: before, a
        Pause pressed then was dropped and the run went on."""
        with self._lock:
            if self._state == RunState.RUNNING:
                self._running.clear()
                self._set_state(RunState.PAUSED)
            elif self._state == RunState.IDLE and not self._abort.is_set():
                self._pause_at_start = True
                self._running.clear()

    def resume(self) -> None:
        """Continue a paused run (or cancel a pause asked before the run began)."""
        with self._lock:
            if self._state == RunState.PAUSED:
                self._set_state(RunState.RUNNING)
                self._running.set()
            elif self._state == RunState.IDLE and self._pause_at_start:
                self._pause_at_start = False
                self._running.set()

    def abort(self, reason: str = "aborted by the user") -> None:
        """Stop at the next point boundary (waits are interrupted); safe state follows."""
        with self._lock:
            if not self._abort.is_set():
                self._abort_reason = reason
                self._abort_t = time.monotonic()
            self._abort.set()
            self._running.set()

    def start(self) -> threading.Thread:
        """Run in a background thread; returns it (join it, or wait for ``finished``)."""
        t = threading.Thread(target=self.run, name="biafc-run-engine", daemon=True)
        self._thread = t
        t.start()
        return t

    def wait(self, timeout_s: float | None = None) -> RunResult | None:
        """Join the thread of :meth:`start`; returns the result (``None`` if still running)."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return self.result

    # -- internals -------------------------------------------------------------------------
    def _set_state(self, new: RunState) -> None:
        with self._lock:
            old, self._state = self._state, new
        if old != new:
            self._emit(
                EventKind.STATE_CHANGED,
                f"{old.value} -> {new.value}",
                state=new.value,
                previous=old.value,
            )

    def _emit(self, kind: EventKind, text: str = "", /, **data: Any) -> None:
        self._bus.emit(RunEvent(kind, text, data))

    def _log(self, level: str, message: str) -> None:
        """A row of the file's ``/log``, a ``biafc.run`` log record (terminal with ``-v``, the log
        file beside the run file) and, for warnings and errors, a WARNING event."""
        _LOGGER.log(_LEVELS.get(level, logging.INFO), message)
        if self._writer is not None and not self._writer.closed:
            try:
                self._writer.log(level, message)
            except Exception:
                pass
        if level in ("warning", "error"):
            self._emit(EventKind.WARNING, message, message=message, level=level)

    def _check_boundary(self) -> None:
        """At a point boundary: honour pause (wait) and abort (raise); a pause and its end are
        recorded in the run's log and file (in the run's thread: the writer's)."""
        if not self._running.is_set():
            t0 = time.monotonic()
            self._log("info", "run paused")
            while not self._running.is_set():
                self._running.wait(0.1)
            if not self._abort.is_set():
                self._log("info", f"run resumed after {time.monotonic() - t0:.1f} s")
        if self._abort.is_set():
            raise _Aborted()

    def _scan_specs(self, time_s: NDArray[np.float64]) -> list[ScanSpec]:
        proto = self.protocol_file.protocol
        specs = []
        for d in self.plan.directions:
            b = proto.burst[d].burst()  # type: ignore[index]
            specs.append(
                ScanSpec(
                    direction=d,
                    amplitudes=self.plan.amplitudes,
                    amplitude_units=self.plan.amplitude_units,
                    cylinders=self.plan.cylinders,
                    time_s=time_s,
                    f_center_Hz=b.f_center_Hz,
                    cycles=b.cycles,
                    width_s=b.width_s,
                    averages=proto.averages,
                    drive_units="V",
                    decoder_delay_undone_s=self._delay_s,
                )
            )
        return specs

    def _acquisition_config(self) -> AcquisitionConfig:
        acq = self.protocol_file.protocol.acquisition
        daq = self.bench_file.bench.daq
        return AcquisitionConfig(
            sample_rate_Hz=acq.rate,
            n_samples=acq.n_samples(),
            n_pretrigger=acq.n_pretrigger,
            velocity_channel=daq.velocity_channel,
            reference_channel=daq.reference_channel,
            velocity_range_V=daq.velocity_range,
            reference_range_V=daq.reference_range,
            trigger_source=daq.trigger,
            timeout_s=acq.timeout,
        )

    def _generator_name(self) -> str:
        from daq.engine.safe_state import generator_name

        return generator_name(self.instruments.generator)

    def _safe_state(self) -> tuple[list[str], list[str]]:
        """:func:`daq.engine.safe_state.bring_to_safe_state` on this bench's outputs:
        ``(problems, unconfirmed)``."""
        from daq.engine.safe_state import bring_to_safe_state

        channels = sorted(set(self.bench_file.bench.direction_channel.values()))
        found = bring_to_safe_state(self.instruments, channels)
        return found.problems, found.unconfirmed

    # -- the run ---------------------------------------------------------------------------
    def run(self) -> RunResult:
        """Run to the end (blocking). Never raises for instrument faults: see ``result``."""
        t0 = time.monotonic()
        status, reason = "failed", ""
        n_done = n_failed = 0
        self._n_already = 0
        self._n_now = 0
        self._n_failed_now = 0
        self._refused = False
        self._awake_note: tuple[str, str] | None = None
        with self._lock:
            if self._state != RunState.IDLE:
                raise RuntimeError("a RunEngine runs once; make a new one")
            self._state = RunState.RUNNING
            self._emit(EventKind.STATE_CHANGED, "idle -> running", state="running", previous="idle")
            if self._pause_at_start and not self._abort.is_set():  # paused before it began:
                self._set_state(RunState.PAUSED)  # the first point boundary waits for Resume
        try:
            with self._awake():
                n_done, n_failed, status, reason = self._run_points(t0)
        except RequestRefused as exc:
            status, reason = "refused", str(exc)
            self._refused = True
        except _Aborted:
            status, reason = "aborted", self._abort_reason or "aborted"
        except KeyboardInterrupt:
            status, reason = "aborted", self._abort_reason or "interrupted (Ctrl-C)"
        except InstrumentError as exc:
            status, reason = "failed", f"{type(exc).__name__}: {exc}"
        except (DiskFull, RunFileError) as exc:  # the run file's disk is full, or failed a write
            status, reason = "failed", str(exc)
        except Exception as exc:
            status, reason = "failed", f"unexpected {type(exc).__name__}: {exc}"
        finally:
            self.ending = True  # a signal handler must not interrupt what follows
            t_end_request = self._abort_t if status == "aborted" and self._abort_t else None
            t_end_request = t_end_request or time.monotonic()
            problems, unconfirmed = self._safe_state()
            safe_s = time.monotonic() - t_end_request
            for p in problems:
                self._log("error", p)
            points_failed_only = status == "failed" and reason.startswith(_POINTS_FAILED)
            if unconfirmed:
                from daq.engine.outcome import unsafe_instruction

                prior = f"{status}" + (f": {reason}" if reason else "")
                status = "unsafe"
                reason = f"safe state not confirmed after the run ended {prior}"
                self._log("error", unsafe_instruction(unconfirmed))
            if self._writer is not None:
                try:
                    n_done = sum(
                        int((self._writer.done_mask(x) == PointState.DONE).sum())
                        for x in self.plan.directions
                    )
                except Exception:
                    pass
                level = "info" if status == "complete" else "error"
                ended = SimpleNamespace(
                    status=status,
                    reason=reason,
                    points_failed_only=points_failed_only,
                    unconfirmed=tuple(unconfirmed),
                )
                # the words the last line and the file's outcome use ("finished with failed
                # points: ...", not "run failed: finished with failed points: ..."); the log
                # says what to switch off by hand on a line of its own (above)
                said = outcome_text(ended)
                logged = outcome_text(SimpleNamespace(**{**vars(ended), "unconfirmed": ()}))
                self._log(level, logged if status != "complete" else "run complete")
                if not unconfirmed:
                    self._log(
                        "info",
                        f"safe state confirmed (outputs read back off) in {safe_s:.2f} s"
                        + ("" if not problems else f" ({len(problems)} problem(s) on the way)"),
                    )
                self._log(
                    "info",
                    f"measured now {self._n_now}, already in the file {self._n_already}, "
                    f"failed {self._n_failed_now} (of {self.plan.n_points})",
                )
                try:
                    self._writer.close(
                        status,  # type: ignore[arg-type]
                        simulation=self._simulation_attrs(),
                        outcome=said,
                    )
                except Exception as exc:  # the file's status is not written: not complete
                    reason = reason or f"closing the run file failed: {exc}"
                    if status == "complete":
                        status = "failed"
            if self._file_lock is not None:
                try:
                    self._file_lock.release()
                except OSError as exc:  # the folder turned read-only: the outcome still stands
                    self._log(
                        "warning",
                        f"the run file's lock {self._file_lock.lock} could not be removed "
                        f"({exc.strerror or exc}); a later run takes it over (its process has "
                        "ended)",
                    )
            self._set_state(RunState(status))
            self.result = RunResult(
                status,
                reason,
                self.out_path,
                n_done,
                n_failed,
                time.monotonic() - t0,
                n_points=self.plan.n_points,
                n_measured_now=self._n_now,
                n_already=self._n_already,
                unconfirmed=tuple(unconfirmed),
                safe_state_s=None if unconfirmed else safe_s,
                points_failed_only=points_failed_only,
                file_written=self._writer is not None,
                resumed=self.resume_mode,
            )
            self._emit(
                EventKind.FINISHED,
                reason or status,
                status=status,
                reason=reason,
                path=str(self.out_path),
                n_done=n_done,
                n_failed=n_failed,
                n_points=self.plan.n_points,
                n_measured_now=self._n_now,
                n_already=self._n_already,
                unconfirmed=list(unconfirmed),
                safe_state_s=self.result.safe_state_s,
                points_failed_only=points_failed_only,
            )
        return self.result

    @property
    def file_broken(self) -> str | None:
        """Why the run file took no more writes (a records write failed: a full disk), else
        ``None``; such a file is left as a killed writer leaves one."""
        return None if self._writer is None else self._writer.broken

    def _simulation_attrs(self) -> dict[str, Any] | None:
        """``/simulation`` attributes of a simulated-bench run: the DEM runs served to this file
        (each with its error estimate; a resume's after those of the sessions before it) and
        their worst indicators; ``None`` otherwise. Before, a resume's attributes described its
        own runs only: the worst error estimate of the file's points was lost."""
        take = getattr(self.instruments.world, "take_dem_runs", None)
        if take is None:
            return None
        try:
            runs: list[dict[str, Any]] = list(take())
        except Exception:
            return None
        if not runs:
            return None
        if self.resume_mode and self._writer is not None:
            try:
                runs = self._writer.earlier_dem_runs() + runs
            except (OSError, ValueError, TypeError):
                pass  # unreadable: this session's runs, as before
        err = [float(r.get("error_estimate_rel", np.nan)) for r in runs]
        res = [float(r.get("work_not_in_chain_rel", np.nan)) for r in runs]
        finite = [x for x in res if np.isfinite(x)]
        missing = self._amplitudes_without_dem_run(runs)
        note = (
            {
                "dem_runs_note": f"{missing} (direction, amplitude) pair(s) with measured points "
                "have no DEM run listed: a session ended without closing the file (killed), so "
                "their error estimates are not in error_estimate_rel"
            }
            if missing
            else {}
        )
        return {
            **note,
            "integrator": str(runs[0].get("integrator", "")),
            "order": int(runs[0].get("order", 0)),
            "dt_s": float(runs[0].get("dt_s", np.nan)),
            "error_estimate_rel": float(np.nanmax(err)) if np.isfinite(err).any() else np.nan,
            "work_not_in_chain_rel": max(finite, key=abs) if finite else float("nan"),
            "dem_runs": len(runs),
            "dem_runs_json": json.dumps(runs, default=float),
        }

    def _amplitudes_without_dem_run(self, runs: list[dict[str, Any]]) -> int:
        """How many (direction, amplitude) pairs of the file have measured points but no DEM
        run listed (one run serves every cylinder of a pair): those of a killed session, whose
        runs were never written (``/simulation`` is written as the file closes)."""
        if self._writer is None:
            return 0
        try:
            measured = sum(
                int(np.any(self._writer.done_mask(d) == PointState.DONE, axis=1).sum())
                for d in self.plan.directions
            )
        except (OSError, KeyError, ValueError):
            return 0
        listed = len({(str(r.get("direction")), float(r.get("amplitude", np.nan))) for r in runs})
        return max(0, measured - listed)

    def _snapshot(self) -> dict[str, Any]:
        """Every instrument's ``snapshot()``, what each reports when asked now (``read_back``:
        identity, outputs, decoder range and sensitivity, stage position, digitiser rate) and,
        on the simulated bench, the model's parameters (``simulation_model``)."""
        inst = self.instruments
        snap = inst.snapshot()
        gen, vib, stage = inst.generator, inst.vibrometer, inst.stage
        channels = sorted(set(self.bench_file.bench.direction_channel.values()))
        asks: dict[str, dict[str, Callable[[], Any]]] = {
            "generator": {
                "identity": gen.identify,
                **{f"output{ch}_on": functools.partial(gen.output_state, ch) for ch in channels},
            },
            "vibrometer": {
                "identity": vib.identify,
                "range": vib.velocity_range,
                "sensitivity_m_per_s_per_V": vib.sensitivity_m_per_s_per_V,
                "signal_delay_s": vib.signal_delay_s,
                "bandwidth_Hz": vib.bandwidth_Hz,
            },
            "stage": {"homed": stage.is_homed, "position_m": stage.position},
        }
        read_back: dict[str, dict[str, Any]] = {}
        for name, items in asks.items():
            read_back[name] = {}
            for key, fn in items.items():
                try:
                    read_back[name][key] = fn()
                except Exception as exc:
                    read_back[name][key] = f"error: {exc}"
        read_back["digitiser"] = {"sample_rate_Hz": getattr(self, "_rate_Hz", None)}
        snap["read_back"] = read_back
        config = getattr(inst.world, "config", None)
        if config is not None:
            from sim_backend.dem.versions import model_version

            snap["simulation_model"] = {**_jsonable(config), "model_version": model_version()}
        return snap

    def _configure_digitiser(self) -> NDArray[np.float64]:
        """Set the vibrometer range and configure the acquisition (both before the snapshot);
        returns the time axis ``[S]`` (s from the trigger)."""
        inst, bench = self.instruments, self.bench_file.bench
        if inst.vibrometer.velocity_range() != bench.vibrometer.range:
            inst.vibrometer.set_velocity_range(bench.vibrometer.range)
        cfg = self._acquisition_config()
        # samples past the window, so that undoing the decoder's delay reads measured data
        # to the window's last sample (decoder_delay.tail_samples)
        delay = float(self._ask("vibrometer", inst.vibrometer.signal_delay_s))
        self._delay_s = delay
        self._tail = tail_samples(delay, cfg.sample_rate_Hz)
        n_window = cfg.n_samples
        cfg = dataclasses.replace(cfg, n_samples=n_window + self._tail)
        rate = float(self.instruments.digitiser.configure(cfg))
        self._rate_Hz = rate
        self._coerced = abs(rate - cfg.sample_rate_Hz) > 1e-6 * cfg.sample_rate_Hz
        return (np.arange(n_window) - cfg.n_pretrigger) / rate

    def _prepare(self, time_s: NDArray[np.float64]) -> None:
        """Outputs off, stage homed (logged in the open run file)."""
        inst, bench = self.instruments, self.bench_file.bench
        if getattr(self, "_coerced", False):
            self._log("warning", f"digitiser rate coerced to {1 / (time_s[1] - time_s[0]):.6g} S/s")
        for ch in sorted(set(bench.direction_channel.values())):
            inst.generator.output(ch, False)
        if not inst.stage.is_homed():
            text = "homing the stage" + _homing_time(inst.stage)
            self._log("info", text)
            self._emit(EventKind.STATUS, text, text=text)
            inst.stage.home(cancel=self._abort)  # an abort stops the axis, not waits for it
            if self._abort.is_set():
                raise _Aborted()

    def _run_points(self, t0: float) -> tuple[int, int, str, str]:
        proto = self.protocol_file.protocol
        inst = self.instruments
        if self._abort.is_set():
            raise _Aborted()
        from daq.store.lock import FileInUse, RunFileLock

        try:
            self._file_lock = RunFileLock(self.out_path).acquire()
        except FileInUse as exc:
            raise RequestRefused(str(exc)) from None
        if self.on_file_locked is not None:
            self.on_file_locked()
        if self.resume_mode:
            # the axes come from the file; the instruments are set up after the checks
            from daq.store import StoreError
            from protocols.runfile import read_run

            try:
                stored = read_run(self.out_path)
                time_s = next(iter(stored.scans.values())).time_s
                self._writer = resume_run(
                    self.out_path,
                    self.protocol_file,
                    self._scan_specs(time_s),
                    bench=self.bench_file,
                    accept_bench_change=self.accept_bench_change,
                    seed=self.seed,
                )
            except StoreError as exc:
                raise RequestRefused(str(exc)) from None
            except (OSError, ValueError, StopIteration) as exc:
                raise RequestRefused(
                    f"--resume: {self.out_path} cannot be continued ({exc})"
                ) from None
            self._log("info", f"resumed (seed {self.seed})")
            overrides = self._writer.attrs_json("bench_overrides_json")
            if overrides:
                self._log(
                    "warning",
                    "resumed on a different bench (--accept-bench-change): "
                    + "; ".join(overrides[-1]["differences"]),
                )
            new_time = self._configure_digitiser()
            if new_time.shape != time_s.shape or not np.allclose(new_time, time_s):
                raise InstrumentError("the digitiser's time axis differs from the file's")
            self._prepare(time_s)
        else:
            time_s = self._configure_digitiser()
            self._writer = create_run(
                self.out_path,
                backend=inst.backend,
                chain=inst.chain,
                scans=self._scan_specs(time_s),
                protocol_yaml=self.protocol_file.text,
                bench_yaml=self.bench_file.text,
                snapshot=self._snapshot(),
                seed=self.seed,
            )
            self._log("info", f"run started: protocol {proto.name!r}, {self.plan.n_points} points")
            self._prepare(time_s)
        writer = self._writer
        if self._file_lock.stale_note:
            self._log("warning", f"{self.out_path.name}: {self._file_lock.stale_note}")
        if self._awake_note is not None:
            self._log(*self._awake_note)
        todo = list(points_left(self.plan, {d: writer.done_mask(d) for d in self.plan.directions}))
        total = self.plan.n_points
        n_done = total - len(todo)
        self._n_already = n_done
        n_failed = 0
        eta = self.plan.eta(tuple(todo))
        self._emit(
            EventKind.RUN_STARTED,
            f"{len(todo)} of {total} points to measure",
            path=str(self.out_path),
            n_points=total,
            n_todo=len(todo),
            n_already=n_done,
            estimated_s=eta.total_s(),
            estimate_basis=eta.costs.basis,
        )
        armed: tuple[str, int] | None = None
        t_start = t_last = time.monotonic()
        in_a_row = 0  # points failed in a row, up to proto.max_failed_in_a_row
        for k, point in enumerate(todo):
            self._check_boundary()
            room_for_a_point(self.out_path, time_s.size, n_done)  # else DiskFull: the run ends
            if armed != (point.direction, point.amplitude_index):
                self._arm_generator(point)
                armed = (point.direction, point.amplitude_index)
            ok = self._measure_point(point, time_s)
            if ok:
                n_done += 1
                self._n_now += 1
                in_a_row = 0
            else:
                n_failed += 1
                self._n_failed_now += 1
                in_a_row += 1
                if 0 < proto.max_failed_in_a_row <= in_a_row:
                    return n_done, n_failed, "failed", self._bench_needs_attention(in_a_row)
                if proto.on_point_failure == "stop":
                    return (
                        n_done,
                        n_failed,
                        "failed",
                        (
                            f"point {point.direction} amplitude {point.amplitude_index + 1} "
                            f"cylinder {point.cylinder} failed after {proto.retries} retries"
                        ),
                    )
            now = time.monotonic()
            # from the end of the last point: what the progress display and the boundary check
            # cost between points counts too (on a loaded machine it is not small)
            eta.measured(now - t_last)
            t_last = now
            left = len(todo) - k - 1
            self._emit(
                EventKind.PROGRESS,
                "",
                done=total - left,
                total=total,
                elapsed_s=now - t_start,
                eta_s=eta.remaining_s(),
                direction=point.direction,
                amplitude=point.amplitude,
                amplitude_units=self.plan.amplitude_units,
                cylinder=point.cylinder,
            )
        self._check_boundary()
        if n_failed:
            self._log("warning", f"{n_failed} point(s) failed and are marked in the file")
            return (
                n_done,
                n_failed,
                "failed",
                f"{_POINTS_FAILED} {n_failed} of {total} points failed (marked in the file); "
                f"re-measure them with --resume {self.out_path}",
            )
        return n_done, n_failed, "complete", ""

    @contextlib.contextmanager
    def _awake(self) -> Iterator[None]:
        """A lab bench's run keeps the computer from sleeping (:mod:`daq.engine.keep_awake`);
        the simulated bench's holds nothing."""
        if self.bench_file.bench.simulation is not None:
            yield
            return
        with keep_awake() as (holder, why_not):
            # logged once the file exists (_run_points): its /log keeps it too
            if holder is not None:
                self._awake_note = ("info", f"the computer is kept awake during the run ({holder})")
            else:
                self._awake_note = ("warning", cannot_line(str(why_not)))
            yield

    def _bench_needs_attention(self, in_a_row: int) -> str:
        """The reason of a run ended by ``in_a_row`` failed points in a row (the last one's
        error is in the log just before)."""
        return (
            f"{in_a_row} points in a row failed (max_failed_in_a_row): the bench needs attention "
            "(the trigger cable, the laser spot, an instrument); the failed points are marked in "
            f"the file: fix the bench, then --resume {self.out_path}"
        )

    def _arm_generator(self, point: Point) -> None:
        """Upload the burst of ``point`` on its direction's channel; only that output on."""
        bench = self.bench_file.bench
        gen = self.instruments.generator
        ch = bench.direction_channel[point.direction]  # type: ignore[index]
        for other in sorted(set(bench.direction_channel.values()) - {ch}):
            gen.output(other, False)
        gen.output(ch, False)
        shape = self.protocol_file.protocol.burst[point.direction].burst()  # type: ignore[index]
        gen.configure_burst(
            ch,
            BurstConfig(
                shape=shape,
                amplitude_Vpp=point.generator_Vpp,
                sample_rate_Hz=bench.generator.sample_rate,
                trigger_source="bus",
            ),
        )
        gen.output(ch, True)
        gen.wait_complete()
        errs = gen.errors()
        if errs:
            raise InstrumentError(f"generator reported: {'; '.join(errs)}")
        # the instruments as set up now: the generator's snapshot (the burst read back, asked
        # here before as well) and the vibrometer's range; the file's /snapshot is taken at
        # creation, before any of it, and a resume takes none. Asked as the run asks: a dead
        # instrument ends the run at its first timeout (a snapshot of every instrument took
        # up to 7 timeouts more on a dead vibrometer; a reviewer)
        gen_snap = self._ask("generator", gen.snapshot)
        vib_range = self._ask("vibrometer", self.instruments.vibrometer.velocity_range)
        snap = {"generator": gen_snap, "read_back": {"vibrometer": {"range": vib_range}}}
        self._log(
            "info",
            f"generator channel {ch}: {point.direction} burst {point.generator_Vpp:.4g} Vpp"
            + _held_text(gen_snap if isinstance(gen_snap, dict) else {}, ch),
        )
        if self._writer is not None:
            self._writer.add_snapshot(point.direction, point.amplitude_index, point.amplitude, snap)

    def _point_data(self, point: Point, attempt: int) -> dict[str, Any]:
        return {
            "direction": point.direction,
            "amplitude_index": point.amplitude_index,
            "cylinder_index": point.cylinder_index,
            "amplitude": point.amplitude,
            "amplitude_units": self.plan.amplitude_units,
            "cylinder": point.cylinder,
            "attempt": attempt,
        }

    def _measure_point(self, point: Point, time_s: NDArray[np.float64]) -> bool:
        """Measure one point with retries; True when written, False when marked failed."""
        proto = self.protocol_file.protocol
        assert self._writer is not None
        last = ""
        for attempt in range(proto.retries + 1):
            if self._abort.is_set():
                raise _Aborted()
            self._emit(EventKind.POINT_STARTED, "", **self._point_data(point, attempt))
            try:
                velocity, drive, sens, delay = self._acquire(point, time_s)
            except (InstrumentTimeout, SignalLostError, PointCheckError) as exc:
                last = f"{type(exc).__name__}: {exc}"
                self._log(
                    "warning",
                    f"{point.direction} A{point.amplitude_index + 1} "
                    f"cyl {point.cylinder} attempt {attempt + 1}: {last}",
                )
                continue
            self._writer.write_point(
                point.direction,
                point.amplitude_index,
                point.cylinder_index,
                velocity,
                drive,
                sensitivity_m_per_s_per_V=sens,
                decoder_delay_undone_s=delay,
            )
            self._emit(
                EventKind.POINT_DONE,
                "",
                velocity_m_per_s=velocity,
                drive=drive,
                time_s=time_s,
                **self._point_data(point, attempt),
            )
            return True
        self._writer.mark_failed(
            point.direction, point.amplitude_index, point.cylinder_index, reason=last
        )
        self._log(
            "error",
            f"{point.direction} A{point.amplitude_index + 1} cyl {point.cylinder} "
            f"failed after {proto.retries + 1} attempts: {last}",
        )
        self._emit(EventKind.POINT_FAILED, last, reason=last, **self._point_data(point, -1))
        return False

    def _ask(self, name: str, fn: Callable[..., Any], *args: Any) -> Any:
        """Call an instrument; a reply that never comes means a dead link
        (:class:`DeadInstrumentError`, not retried)."""
        try:
            return fn(*args)
        except InstrumentTimeout as exc:
            where = self._generator_name() if name == "generator" else name
            raise DeadInstrumentError(f"{where} stopped answering: {exc}") from exc

    def _check_signal(self, point: Point, when: str = "") -> None:
        """:class:`SignalLostError` when the vibrometer's signal level is below the bench's
        ``vibrometer.min_signal_level``."""
        level = float(self._ask("vibrometer", self.instruments.vibrometer.signal_level))
        floor = self.bench_file.bench.vibrometer.min_signal_level
        if level < floor:
            raise SignalLostError(
                f"vibrometer signal level {level:.2f} below {floor:.2f} at cylinder "
                f"{point.cylinder}" + (f" ({when})" if when else "")
            )

    def _acquire(
        self, point: Point, time_s: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
        """Move, settle, check the signal, take ``averages`` records; velocity (m/s) and drive
        (V), each ``[S]``, and the vibrometer's sensitivity (m/s per V) and decoder delay (s)
        they were made with."""
        proto, bench, inst = self.protocol_file.protocol, self.bench_file.bench, self.instruments
        ask = self._ask
        ask("stage", inst.stage.move_to, point.position_m)
        if not inst.wait(proto.settle, self._abort):
            raise _Aborted()
        self._check_signal(point)
        sens = float(ask("vibrometer", inst.vibrometer.sensitivity_m_per_s_per_V))
        delay = float(ask("vibrometer", inst.vibrometer.signal_delay_s))
        clip_V = CLIP_FRACTION * bench.daq.velocity_range
        v_sum = np.zeros(time_s.shape[0] + self._tail)
        d_sum = np.zeros(time_s.shape[0] + self._tail)
        for _ in range(proto.averages):
            if self._abort.is_set():
                raise _Aborted()
            inst.digitiser.arm()
            ask("generator", inst.generator.trigger)
            try:
                rec = inst.digitiser.read()
            except InstrumentTimeout:
                # no trigger: a generator that stopped answering ends the run now, not
                # after every retry of every point timed out
                ask("generator", inst.generator.wait_complete)
                raise
            # after each record as well: a signal lost while averaging left a point "done"
            # at half its velocity (one of two records empty)
            self._check_signal(point, "after a record")
            v = np.asarray(rec.velocity_V, dtype=np.float64)
            d = np.asarray(rec.reference_V, dtype=np.float64)
            n_read = time_s.shape[0] + self._tail  # the window and its tail
            if v.shape != (n_read,) or d.shape != (n_read,):
                raise PointCheckError(f"record of {v.shape} samples, expected ({n_read},)")
            if not (np.all(np.isfinite(v)) and np.all(np.isfinite(d))):
                raise PointCheckError("record holds NaN or infinite samples")
            if np.max(np.abs(v)) >= clip_V:
                raise PointCheckError(
                    f"velocity clipped at {clip_V:.3g} V: choose a larger vibrometer range"
                )
            v_sum += v
            d_sum += d
        errs = ask("generator", inst.generator.errors)
        if errs:  # an error the generator queued while playing: the records cannot be trusted
            raise InstrumentError(f"generator reported: {'; '.join(errs)}")
        v_mean = v_sum / proto.averages * sens
        if delay != 0.0:  # the decoder output lags: v_true(t) = v_out(t + delay)
            v_mean = undo_decoder_delay(v_mean, self._rate_Hz, delay)
        n = time_s.shape[0]
        return v_mean[:n], d_sum[:n] / proto.averages, sens, delay
