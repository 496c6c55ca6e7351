"""``run_protocol PROTOCOL.yaml [--bench BENCH.yaml] [--out RUN.h5] [--resume RUN.h5] [--dry-run]``
or ``run_protocol --resume RUN.h5``

Runs a protocol on a bench (default: the shipped simulated bench) into an HDF5 run file.
Everything is checked before an instrument moves; a bad input is one line on stderr, exit 2.
Exit statuses (:mod:`daq.engine.outcome`): 0 complete; 1 failed or aborted; 2 refused before
anything moved; 3 unsafe (the generator's outputs could not be confirmed off: the last line
says what to switch off by hand); 4 finished with failed points (``--resume`` re-measures
them); 130 Ctrl-C. The last line always says what happened; progress is a bar with ETA on a
terminal, plain lines when piped.

``--resume RUN.h5`` alone continues a run with the protocol stored in the file, on the bench
stored in it (unless ``--bench`` is given); with a protocol given, that protocol must be the
file's.

Ctrl-C is handled from the first moment: while the bench is being connected (nothing driven
yet) it stops at once; during the run the first Ctrl-C aborts at the next boundary (waits are
interrupted), a second one interrupts whatever runs; either way the safe state follows and the
time it took is shown.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType
from typing import Any, TextIO

from daq.cli.biafc import CliError
from daq.cli.stop_signals import leave_the_terminal, stop_signals
from protocols.one_line import first_line

__all__ = ["add_arguments", "main", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "protocol",
        type=Path,
        nargs="?",
        default=None,
        help="protocol file (YAML) or the name of a shipped protocol; optional with --resume "
        "(the file's own protocol is used)",
    )
    parser.add_argument(
        "--bench",
        type=Path,
        default=None,
        help="bench file (default: the simulated bench; with --resume, the file's bench)",
    )
    parser.add_argument("--out", type=Path, default=None, help="run file to write (HDF5)")
    parser.add_argument(
        "--resume", type=Path, default=None, metavar="RUN.h5", help="continue an interrupted run"
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="validate, print point count and ETA, run nothing"
    )
    parser.add_argument(
        "--accept-bench-change",
        action="store_true",
        help="with --resume: continue although the bench differs from the file's "
        "(the differences and the new bench are recorded in the file)",
    )
    parser.add_argument("--seed", type=int, default=None, help="seed of the simulated bench")
    parser.add_argument(
        "--set",
        dest="settings",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a setting of the simulated bench's chain (diameter=12mm, preload=4N; "
        "repeatable); recorded in the run file's bench text",
    )
    from daq.logsetup import add_verbosity_arguments

    add_verbosity_arguments(parser)


def _fmt_s(s: float) -> str:
    from daq.progress import format_duration

    return format_duration(s)


def _fmt_amplitude(value: float, units: str) -> str:
    from instruments.units import format_quantity

    if units == "m":
        return format_quantity(value, "length", digits=3)
    return f"{value:.3g} Vpp" if units == "V" else f"{value:.3g} {units}"


class Progress:
    """Shows engine events through :class:`daq.progress.ProgressDisplay`: a live bar with rate
    and ETA on a terminal, plain lines otherwise; warnings as lines of their own."""

    def __init__(self, stream: TextIO, quiet: bool = False) -> None:
        self.stream = stream
        self.quiet = quiet
        self.display: Any = None

    def __call__(self, event: Any) -> None:
        from daq.engine import EventKind
        from daq.progress import ProgressDisplay

        if self.quiet:
            return
        k, d = event.kind, event.data
        if k == EventKind.RUN_STARTED:
            print(
                f"run {d['path']}: {d['n_todo']} of {d['n_points']} points to measure "
                f"(estimated {_fmt_s(d['estimated_s'])} from "
                f"{d.get('estimate_basis') or 'the plan'})",
                file=self.stream,
                flush=True,
            )
            self.display = ProgressDisplay(
                int(d["n_points"]),
                unit="point",
                label="measuring",
                stream=self.stream,
                start_done=int(d.get("n_already", 0)),
            )
        elif k == EventKind.PROGRESS and self.display is not None:
            amp = _fmt_amplitude(float(d["amplitude"]), str(d["amplitude_units"]))
            where = f"{d['direction']} {amp} cyl {d['cylinder']:2d}"
            self.display.update(int(d["done"]), detail=where, eta_s=float(d["eta_s"]))
        elif k == EventKind.STATUS:  # homing: minutes on the rig, before the first point
            if self.display is not None:
                self.display.note(str(d["text"]))
            else:
                print(str(d["text"]), file=self.stream, flush=True)
        elif k == EventKind.WARNING:
            text = f"warning: {event.message}"
            if self.display is not None:
                self.display.note(text)
            else:
                print(text, file=self.stream, flush=True)
        elif k == EventKind.FINISHED and self.display is not None:
            self.display.close()


def _request(args: argparse.Namespace) -> Any:
    """The whole request (protocol x bench x output x resume file) validated by
    :func:`daq.request.validate_request`, the one path to a run: nothing is opened or written
    before it says yes; a refusal is one line (exit 2)."""
    from daq.request import RequestError, validate_request

    try:
        return validate_request(
            args.protocol,
            args.bench,
            out=args.out,
            resume=args.resume,
            settings=tuple(getattr(args, "settings", ()) or ()),
            seed=args.seed,
            accept_bench_change=getattr(args, "accept_bench_change", False),
        )
    except RequestError as exc:
        raise CliError(str(exc)) from None


def run(args: argparse.Namespace) -> int:
    req = _request(args)
    pf, bf, plan, out = req.protocol, req.bench, req.plan, req.out
    if args.dry_run:
        from daq.engine.eta import homing_note

        basis = plan.costs.basis if plan.costs is not None else "the plan"
        points, estimated_s = f"{plan.n_points} points", plan.estimated_s
        if req.resume:  # what the resume measures, not the whole plan
            todo = _points_left_in(out, plan)
            points = f"{len(todo)} of {plan.n_points} points to measure"
            estimated_s = plan.eta(todo).total_s()
        print(
            f"protocol {pf.protocol.name!r} on {bf.bench.name!r}: {points}, "
            f"estimated {_fmt_s(estimated_s)} ({estimated_s:.1f} s, from {basis}); "
            f"output {out}{homing_note(bf)}"
        )
        return 0
    return _execute(pf, bf, out, req.resume, req.seed, args.quiet, req.accept_bench_change)


def _points_left_in(out: Path, plan: Any) -> tuple[Any, ...]:
    """The points of ``plan`` the run file ``out`` does not hold as measured (read only)."""
    import numpy as np

    from daq.engine.plan import points_left
    from protocols.runfile import open_for_reading

    with open_for_reading(out) as f:
        done = {d: np.asarray(f["scan"][d]["done"][...]) for d in plan.directions}
    return points_left(plan, done)


class _Interrupted(KeyboardInterrupt):
    """Ctrl-C/SIGTERM before the engine runs, or a second one (or the watchdog) during it."""


#: after the first Ctrl-C, the run has this long to reach its safe state by itself (a point in
#: flight, homing, a DEM being compiled); then it is interrupted where it is, and the safe
#: state follows at once
ABORT_BOUND_S = 5.0

#: a closing console window (Windows): the abort is forced after this long (s), and the handler
#: gives up at :data:`daq.cli.console_close.CLOSE_BOUND_S`
CLOSE_GRACE_S = 2.0


class _SignalGate:
    """SIGINT/SIGTERM (and SIGHUP, :func:`stop_signals`) from the first moment of ``main``:
    before the engine exists a signal stops at once (nothing was switched on); during the run
    the first asks the engine to abort and starts a watchdog of :data:`ABORT_BOUND_S`; a second
    one, or the watchdog, interrupts whatever runs. Never while the safe state is being set and
    the file closed."""

    def __init__(self) -> None:
        self.engine: Any = None
        self.interrupted: list[str] = []
        #: set once a run's outcome is in its log and file (what a closing console waits for)
        self.outcome_written = threading.Event()
        self.ran = False  # an engine was made: the bench may be driven
        self._watchdog: threading.Timer | None = None
        self._forced = False
        self._old: dict[int, Any] = {}
        self._console: Any = None

    def install(self) -> _SignalGate:
        from daq.cli.console_close import hold_console_close

        self._old = {s: signal.signal(s, self) for s in stop_signals()}
        self._console = hold_console_close(self.console_closed)  # Windows only
        return self

    def restore(self) -> None:
        if self._watchdog is not None:
            self._watchdog.cancel()
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old = {}
        if self._console is not None:
            self._console.remove()
            self._console = None

    def console_closed(self, what: str) -> None:
        """Windows' handler thread, the console window closing (or a log-off, a shutdown):
        Windows ends the process when this returns, or after about 5 s. As SIGHUP: the output
        to the null device and the run aborted; then wait until its outcome is written, the
        abort forced after :data:`CLOSE_GRACE_S`, for
        :data:`~daq.cli.console_close.CLOSE_BOUND_S` in all."""
        from daq.cli.console_close import CLOSE_BOUND_S

        leave_the_terminal()
        if not self.ran:
            return  # nothing driven yet: nothing to put in a safe state
        self.interrupted.append(what)
        engine = self.engine
        if engine is not None and not engine.ending:
            engine.abort(f"interrupted: {what}")
        if not self.outcome_written.wait(CLOSE_GRACE_S):
            engine = self.engine
            if engine is not None and not engine.ending:
                self._force()
            self.outcome_written.wait(CLOSE_BOUND_S - CLOSE_GRACE_S)

    def _force(self) -> None:
        self._forced = True
        main = threading.main_thread().ident
        if main is None:
            return
        if hasattr(signal, "pthread_kill"):  # a real signal: it breaks a blocking wait there too
            signal.pthread_kill(main, signal.SIGINT)
        else:  # Windows: raised in the process, whose SIGINT event also ends a wait
            signal.raise_signal(signal.SIGINT)

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if name == "SIGHUP":
            leave_the_terminal()
        if self._forced:
            self._forced = False
            name = self.interrupted[0] if self.interrupted else name
        else:
            self.interrupted.append(name)
        engine = self.engine
        if engine is not None and engine.ending:
            return  # the safe state is being set and the file closed: never interrupt that
        if engine is None or len(self.interrupted) > 1 or self._watchdog is not None:
            raise _Interrupted(name)  # nothing driven yet, asked twice, or too slow: stop now
        engine.abort(f"interrupted by {name}")
        self._watchdog = threading.Timer(ABORT_BOUND_S, self._force)
        self._watchdog.daemon = True
        self._watchdog.start()
        print(
            f"run_protocol: {name}: aborting, the run stops within {ABORT_BOUND_S:g} s and "
            "the safe state follows (longer when an instrument does not answer; Ctrl-C again "
            "to hurry)",
            file=sys.stderr,
            flush=True,
        )


_GATE: _SignalGate | None = None


def _execute(
    pf: Any,
    bf: Any,
    out: Path,
    resume: bool,
    seed: int | None,
    quiet: bool,
    accept_bench_change: bool = False,
) -> int:
    import logging

    from daq.engine.outcome import ExitCode, exit_code, final_line
    from daq.logsetup import detach, hold_run_log
    from protocols.left_open import exit_leaving_them, files_left_open

    log = logging.getLogger("biafc.run_protocol")
    # RUN.log beside the run file, everything from INFO up: opened once the run file is ours
    log_file = hold_run_log(out)
    log.info(
        "%s %s on %r into %s", "resuming" if resume else "starting", pf.protocol.name,
        bf.bench.name, out,
    )  # fmt: skip
    gate = _GATE or _SignalGate().install()
    if bf.bench.simulation is not None and not quiet:  # say now that the first point compiles
        from daq.cli import compile_notice
        from sim_backend.dem.kernel_cache import announce_if_cold

        compile_notice.install()
        announce_if_cold()
    try:
        try:
            gate.engine, instruments = _connect(
                pf, bf, out, resume, seed, accept_bench_change, on_file_locked=log_file.open_file
            )
        except _Interrupted as exc:
            print(
                f"run_protocol: interrupted by {exc} while connecting the bench: nothing was "
                "switched on, no file written",
                file=sys.stderr,
            )
            return int(ExitCode.INTERRUPTED if str(exc) == "SIGINT" else ExitCode.FAILED)
        except _ConnectFailed as exc:  # exit 1, as biafc check's "did not answer"
            print(
                f"run_protocol: cannot connect the bench: {exc}; nothing was switched on, no "
                "file written",
                file=sys.stderr,
            )
            return int(ExitCode.FAILED)
        engine = gate.engine
        gate.ran = True
        engine.subscribe(Progress(sys.stdout, quiet))
        try:
            try:
                result = engine.run()
            except _Interrupted:  # raised outside the engine's own handling: already safe
                result = engine.result
            if result is None:
                raise RuntimeError("the run engine returned no result")
        finally:
            instruments.close()
    finally:
        gate.engine = None
        if gate._watchdog is not None:
            gate._watchdog.cancel()
        if gate is not _GATE:
            gate.restore()
        if "result" not in locals():
            detach(log_file)
    code = exit_code(result, sigint="SIGINT" in gate.interrupted)
    line = final_line(result)
    log.log(
        logging.INFO if code == ExitCode.COMPLETE else logging.ERROR, "%s (exit %d)", line, code
    )
    detach(log_file)
    gate.outcome_written.set()
    try:
        print(line, file=sys.stdout if code == ExitCode.COMPLETE else sys.stderr, flush=True)
    except OSError:  # the terminal is gone (SIGHUP ignored): the log file has the line
        leave_the_terminal()
    if files_left_open():  # HDF5's clean-up crashes the process at its exit (139)
        exit_leaving_them(int(code))
    return int(code)


class _ConnectFailed(Exception):
    """An instrument of the bench did not answer while connecting (one line)."""


def _connect(
    pf: Any,
    bf: Any,
    out: Path,
    resume: bool,
    seed: int | None,
    accept_bench_change: bool,
    on_file_locked: Callable[[], None] | None = None,
) -> tuple[Any, Any]:
    from daq.connect import connect_bench
    from daq.engine import RunEngine
    from instruments.errors import DriverNotInstalledError, InstrumentError
    from protocols.yamlfile import ConfigError

    try:
        instruments = connect_bench(bf, seed=seed)
    except (ConfigError, DriverNotInstalledError) as exc:  # the bench file, the installation
        raise CliError(first_line(exc)) from None  # (a driver), the bench in use: 2
    except InstrumentError as exc:  # an instrument that does not answer: not a refused request
        raise _ConnectFailed(first_line(exc)) from None
    engine = RunEngine(
        pf,
        bf,
        instruments,
        out,
        resume=resume,
        seed=seed,
        accept_bench_change=accept_bench_change,
        on_file_locked=on_file_locked,
    )
    return engine, instruments


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="run_protocol", description="Run a measurement protocol into an HDF5 run file."
    )
    global _GATE
    gate = _GATE = _SignalGate().install()  # Ctrl-C is clean from here on
    try:
        add_arguments(parser)
        args = parser.parse_args(argv)
        from daq.logsetup import configure, verbosity

        configure(verbosity(args))
        return run(args)
    except CliError as exc:
        print(f"run_protocol: error: {exc}", file=sys.stderr)
        return 2
    except _Interrupted as exc:
        print(
            f"run_protocol: interrupted by {exc} before the run started: nothing was switched "
            "on, no file written",
            file=sys.stderr,
        )
        return 130 if str(exc) == "SIGINT" else 1
    finally:
        _GATE = None
        gate.restore()


if __name__ == "__main__":
    sys.exit(main())
