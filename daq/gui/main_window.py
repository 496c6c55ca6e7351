"""The bench window: bench panel, protocol panel, run controls, log and live views.

Threading: the run engine runs on its own thread (:meth:`daq.engine.RunEngine.start`); its
events reach :meth:`MainWindow._on_events` through :class:`EngineEventAdapter` (a queued Qt
signal). Connecting, instrument snapshots, safe state, reading run files and exporting
figures run through :class:`BackgroundCall`. The GUI thread only draws.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QAction, QCloseEvent
from PySide6.QtWidgets import (
    QApplication,
    QFileDialog,
    QMainWindow,
    QMessageBox,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from daq.cli.console_close import CLOSE_BOUND_S
from daq.engine.eta import homing_note
from daq.gui import gui_gc, refcount_guard
from daq.gui.adapter import EngineEventAdapter
from daq.gui.background import BackgroundCall
from daq.gui.live_data import LiveData
from daq.gui.panels import BenchPanel, LogView, ProtocolPanel, RunPanel, format_duration
from daq.gui.redraw_pace import FASTEST_MS, RedrawPace
from daq.gui.views import LiveViews
from daq.gui.window_words import in_window_words

__all__ = ["Assembler", "MainWindow"]

#: builds the instruments of a bench file (default: :func:`daq.connect.connect_bench`)
Assembler = Callable[[Any, "int | None"], Any]

#: how long the window waits for a run's safe state when its display is gone (s): as long as
#: a window closed during a run waits
DISPLAY_LOST_BOUND_S = 60.0

#: ms between redraws of the live views while events arrive, at the fastest (slower while
#: drawing takes most of the window's time: :mod:`daq.gui.redraw_pace`)
REDRAW_MS = FASTEST_MS


def _default_assembler(bf: Any, seed: int | None) -> Any:
    from daq.connect import connect_bench

    return connect_bench(bf, seed=seed)


def shown_path(path: str | Path) -> str:
    """``path`` as the window shows it: relative to the working folder when inside it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return str(p)


class MainWindow(QMainWindow):
    """The bench window.

    Parameters
    ----------
    bench_path:
        Bench file; ``None``: the shipped simulated bench.
    protocol_path:
        Protocol file to open at start (optional).
    assembler:
        ``assembler(bench_file, seed) -> BenchInstruments`` (tests pass fakes).
    """

    #: emitted with the run's status when a run ends: "complete" | "aborted" | "failed" (also
    #: finished with failed points: the run panel's line tells them apart) | "unsafe" | "refused"
    run_finished = Signal(str)
    #: emitted when a bench connection attempt ends (True: connected)
    connected = Signal(bool)
    #: (phase, elapsed s, cache folder, cold) of a first-use compilation of the DEM kernel, from
    #: whichever thread compiles (the run engine's): shown on the GUI thread
    compile_progress = Signal(str, float, str, bool)

    def __init__(
        self,
        bench_path: str | Path | None = None,
        protocol_path: str | Path | None = None,
        *,
        assembler: Assembler | None = None,
    ) -> None:
        super().__init__()
        refcount_guard.install()
        gui_gc.install()  # garbage collected on this thread only, never in a worker
        self.setWindowTitle("biafc-lab — bench")
        self.resize(1500, 950)
        self._assembler = assembler or _default_assembler
        self.bench_file: Any = None
        #: the one-line error of a bench file that did not load while no bench is loaded
        self._bench_error: str | None = None
        self.instruments: Any = None
        self.chain: Any = None
        self.protocol_file: Any = None
        self.protocol_path: Path | None = None
        self.plan: Any = None
        self.engine: Any = None
        self.adapter: EngineEventAdapter | None = None
        #: the engine's FINISHED is not handled yet (:attr:`running`)
        self._run_open = False
        #: the bench panel's "UNSAFE" of a run that could not confirm its safe state: up until
        #: a safe state is confirmed (:meth:`_clear_unsafe_mark`), whatever else the panel says
        self._unsafe_mark: str | None = None
        #: the instruments the UNSAFE run ran on (:func:`_bench_identity`): only their
        #: read-back takes it down
        self._unsafe_bench: tuple[str, ...] | None = None
        #: a run file opened during a run: read and shown once the run has ended
        self._open_after_run: tuple[Path, Callable[[bool], None] | None] | None = None
        self.live = LiveData()
        self.last_result: Any = None
        #: the process's exit status, as run_protocol's: the last run's (0 complete, 1 failed
        #: or aborted, 3 unsafe, 4 points failed; a run aborted by closing the window too);
        #: closed by a stop signal while no run was active, 128 + the signal; 0 without a run
        self.exit_status = 0
        #: the stop signal that closes the window (:meth:`stop_signal`), or None
        self._stop_signal: int | None = None
        self._closing = False  # a close is waiting for the run's safe state
        self._closed = False  # the window has closed (:meth:`_finish_close`)
        self._asking_close = False  # Close's question (confirm_close) is on screen
        self.run_path: Path | None = None
        self._dirty = False
        self._busy_connect = False
        self._pending_start: tuple[Path | None] | None = None
        #: a resumed run's file whose points are being read before it starts (None: none)
        self._prefilling: Path | None = None
        #: what works on the instruments now, besides a run (a Safe state, a read of their
        #: state): Start waits for them
        self._busy: list[str] = []
        #: held by every worker of the window that talks to the instruments (a read of their
        #: state, the Safe state, closing them): one at a time on the transports, without the
        #: GUI thread waiting (the Safe state clicked during the post-run read ran beside it)
        self._instrument_lock = threading.Lock()
        # the model (numba, the compiled kernel, the chain's tools) loads here, before the
        # window turns, not on the event loop or beside it when the first run starts
        import analysis.model_overlay  # noqa: F401
        import sim_backend.dem

        for name in sim_backend.dem.__all__:
            getattr(sim_backend.dem, name)

        self._build()
        self._set_startable(False)  # until a protocol in the editor validates
        # the kernel compiles on the engine's thread at the first simulated point: said here,
        # as the command line says it (the window showed "homing the stage" for 18 s)
        from sim_backend.dem.kernel_cache import set_compile_reporter

        self.compile_progress.connect(self._show_compile)

        def report(phase: str, t: float, folder: Any, cold: bool) -> None:
            try:
                self.compile_progress.emit(phase, t, str(folder), cold)
            except RuntimeError:  # the window is gone: nothing to show it in
                pass

        report.biafc_window = True  # type: ignore[attr-defined]
        self._report = report
        previous = set_compile_reporter(report)
        # another window's is not kept: it may be closed when this one closes
        self._previous_reporter = None if getattr(previous, "biafc_window", False) else previous
        self._redraw_timer = QTimer(self)
        self._redraw_timer.setInterval(REDRAW_MS)
        self._pace = RedrawPace()
        self._redraw_timer.timeout.connect(self._redraw_if_dirty)
        self._redraw_timer.start()
        self.load_bench(bench_path)
        if protocol_path is not None:
            self.load_protocol(protocol_path)

    # -- layout ----------------------------------------------------------------------------
    def _lock_for_run(self, active: bool) -> None:
        """During a run the bench and the protocol are the run's: before, Reconnect stayed
        enabled and did nothing, and the editor took edits that the panel then showed as if
        they had run."""
        bp, pp = self.bench_panel, self.protocol_panel
        for button in (bp.open_button, pp.open_button):
            button.setEnabled(not active)
        bp.connect_button.setEnabled(not active and self.bench_file is not None)  # a bad file:
        # its error said, nothing to connect to
        for action in self._run_locked_actions:  # File → Open bench… / Open protocol… too:
            action.setEnabled(not active)  # before, they replaced the editor mid-run
        bp.refresh_button.setEnabled(not active and self.instruments is not None)
        pp.editor.setReadOnly(active)
        # a dry run checks the output as a new run would: during a run it named this window
        # as "the other writer" of a file (its own PID)
        pp.dry_button.setEnabled(not active and pp.valid)

    def _locked(self, fn: Callable[[], Any]) -> Callable[[], Any]:
        """``fn`` run under the window's instrument lock (on the worker that calls it)."""

        def call() -> Any:
            with self._instrument_lock:
                return fn()

        return call

    def _hold_instruments(self, what: str) -> None:
        self._busy.append(what)
        self.run_panel.set_blocked(True)
        self.bench_panel.refresh_button.setEnabled(False)

    def _release_instruments(self, what: str) -> None:
        if what in self._busy:
            self._busy.remove(what)
        if not self._busy:
            self.run_panel.set_blocked(False)
            self.bench_panel.refresh_button.setEnabled(
                self.instruments is not None and not self.running
            )

    def _build(self) -> None:
        self.bench_panel = BenchPanel()
        self.protocol_panel = ProtocolPanel()
        self.run_panel = RunPanel()
        self.log_view = LogView()
        self.views = LiveViews()
        self.views.on_model_error = lambda msg: self.log(msg, "warning")
        left = QSplitter(Qt.Orientation.Vertical)
        left.addWidget(self.bench_panel)
        left.addWidget(self.protocol_panel)
        left.setStretchFactor(0, 2)
        left.setStretchFactor(1, 3)
        right = QSplitter(Qt.Orientation.Vertical)
        right.addWidget(self.views)
        bottom = QWidget()
        bl = QVBoxLayout(bottom)
        bl.setContentsMargins(0, 0, 0, 0)
        bl.addWidget(self.run_panel)
        bl.addWidget(self.log_view, 1)
        right.addWidget(bottom)
        right.setStretchFactor(0, 3)
        right.setStretchFactor(1, 1)
        main = QSplitter(Qt.Orientation.Horizontal)
        main.addWidget(left)
        main.addWidget(right)
        main.setStretchFactor(0, 2)
        main.setStretchFactor(1, 5)
        main.setSizes([480, 1020])
        right.setSizes([640, 310])
        self.setCentralWidget(main)
        self.statusBar().showMessage("ready")
        self._menus()
        bp, pp, rp = self.bench_panel, self.protocol_panel, self.run_panel
        bp.open_requested.connect(self._ask_bench)
        bp.connect_requested.connect(self.connect_bench)
        bp.refresh_requested.connect(self.refresh_snapshot)
        bp.safe_state_requested.connect(self.safe_state)
        pp.open_requested.connect(self._ask_protocol)
        pp.save_requested.connect(self.save_protocol)
        pp.dry_run_requested.connect(self.dry_run)
        pp.text_edited.connect(self._validate_text)
        rp.active_changed.connect(self._lock_for_run)
        rp.start_requested.connect(self.start_run)
        rp.pause_requested.connect(self.pause)
        rp.resume_requested.connect(self.resume)
        rp.abort_requested.connect(self.abort)
        rp.resume_file_requested.connect(self._ask_resume_file)

    def _menus(self) -> None:
        m = self.menuBar().addMenu("&File")
        #: the menu's twins of the panels' Open… buttons: locked with them during a run
        self._run_locked_actions: list[QAction] = []
        for text, slot in (
            ("Open bench…", self._ask_bench),
            ("Open protocol…", self._ask_protocol),
            ("Save protocol", self.save_protocol),
            ("Open run file…", self._ask_run_file),
            ("Export figures…", self._ask_export),
        ):
            act = QAction(text, self)
            act.triggered.connect(slot)
            m.addAction(act)
            if slot in (self._ask_bench, self._ask_protocol):
                self._run_locked_actions.append(act)
        m.addSeparator()
        quit_act = QAction("Quit", self)
        quit_act.triggered.connect(self.close)
        m.addAction(quit_act)

    # -- helpers ---------------------------------------------------------------------------
    def log(self, message: str, level: str = "info", *, record: bool = True) -> None:
        """A line in the window's log, and a ``biafc.gui`` record (terminal with ``-v``, the log
        file beside the run file while a run is on: :mod:`daq.logsetup`); ``record=False``: the
        window only, for what the engine has recorded itself (its warnings, its status)."""
        levels = {"warning": logging.WARNING, "error": logging.ERROR}
        if record:
            logging.getLogger("biafc.gui").log(levels.get(level, logging.INFO), message)
        message = in_window_words(message)  # the window's controls, not run_protocol's flags
        self.log_view.add(message, level)
        if level != "info":
            self.statusBar().showMessage(message, 10000)

    @property
    def running(self) -> bool:
        """True while a run is active: from Start (the engine made, its thread perhaps not yet
        begun) until the window has handled the engine's FINISHED. Before, only the engine's
        state counted: in the gap after Start, Abort and Close were ignored (the run went on,
        or its transports were closed under it), and after an UNSAFE end not yet handled,
        Close skipped the question and exited 0."""
        return self.engine is not None and self._run_open

    def _handle_ended_run(self) -> None:
        """The run's FINISHED, if the engine has ended and the window has not handled it yet
        (the GUI thread was busy): handled now, so the window's outcome is the run's."""
        engine = self.engine
        if engine is None or not self._run_open or engine.result is None:
            return
        engine.wait(5.0)  # FINISHED is emitted just after the result is set
        if self.adapter is not None:
            self._on_events()

    # -- bench -----------------------------------------------------------------------------
    def _ask_bench(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open bench", "", "Bench files (*.yaml)")
        if path:
            self.load_bench(path)

    def load_bench(self, path: str | Path | None) -> bool:
        """Read and validate a bench file (``None``: the simulated bench). No instrument is
        opened; :meth:`connect_bench` does that."""
        from protocols.bench import default_bench_path, load_bench
        from protocols.yamlfile import ConfigError

        if self.running:
            self.log("cannot change the bench during a run", "warning")
            return False
        try:
            bf = load_bench(path)
        except (ConfigError, OSError) as exc:
            if self.bench_file is not None:  # refused: the bench loaded stays, and is said
                # (before, the panel kept its path while the line showed the new file's error)
                old = self.bench_file.bench.name
                state = (
                    f"connected ({self.instruments.backend})"
                    if self.instruments is not None
                    else "not connected"
                )
                where = self.bench_panel.path_edit.text()
                line = f"bench file refused: {exc}; still using {old!r} ({where}, {state})"
                self._bench_status(f"✗ {line}", "QLabel { color: #b00000; }")
                self.log(line, "error")
                return False
            self._bench_status(f"✗ {exc}")
            self.log(str(exc), "error")
            # no bench to connect to or to run on: said as such (before, the protocol read
            # valid, Start was on, Connect silent)
            self._bench_error = str(exc)
            self.bench_panel.connect_button.setEnabled(False)
            self.run_panel.set_bench_ok(False)  # Resume file… too, as Start
            self.bench_panel.path_edit.setText(shown_path(path) if path is not None else "")
            if self.protocol_panel.editor.toPlainText().strip():
                self.protocol_panel.validate_now()
            return False
        self._disconnect()
        self.bench_file = bf
        self._bench_error = None
        self.run_panel.set_bench_ok(True)
        shown = Path(path) if path is not None else default_bench_path()
        self.bench_panel.path_edit.setText(shown_path(shown))
        kind = "simulated" if bf.bench.simulated else "hardware"
        self._bench_status(
            f"{bf.bench.name} ({kind}, {bf.bench.n_cylinders} cylinders): not connected"
        )
        self.log(f"bench {bf.bench.name!r} loaded ({kind})")
        self._load_chain(bf)
        if self.protocol_panel.editor.toPlainText().strip():
            self.protocol_panel.validate_now()
        return True

    def _load_chain(self, bf: Any) -> None:
        from daq.chain_info import chain_info

        def done(chain: Any, err: BaseException | None) -> None:
            if bf is not self.bench_file:
                return
            if err is not None:
                self.log(f"quasi-bands of the chain: {err}", "warning")
                return
            if self.chain is None:  # a connected bench's chain wins
                self.chain = chain
                self.views.show_chain(chain, self._f_in())
                self.live.chain = self.live.chain or chain

        BackgroundCall(lambda: chain_info(bf), done, name="biafc-gui-chain")

    def _set_model_for_bench(self, bf: Any, pf: Any = None) -> None:
        """The "model" overlay of a run about to start: the bench's chain, gain and stroke, the
        run's protocol ``pf`` (default: the editor's)."""
        from analysis.model_overlay import ModelOverlay
        from daq.chain_info import chain_spec

        proto = (pf if pf is not None else self.protocol_file).protocol
        try:
            overlay = ModelOverlay.for_bench(bf.bench, proto, chain_spec(bf))
        except Exception as exc:
            self.log(f"model overlay unavailable: {exc}", "warning")
            overlay = None
        self.views.set_model(overlay)

    def _set_model_for_run(self, run: Any) -> None:
        """The "model" overlay of an opened run file: its bench and the chain it records."""
        from analysis.model_overlay import ModelOverlay

        try:
            overlay = ModelOverlay.for_run(run)
        except Exception as exc:
            self.log(f"model overlay unavailable: {exc}", "warning")
            overlay = None
        self.views.set_model(overlay)

    def _disconnect(self) -> None:
        inst, self.instruments = self.instruments, None
        self.chain = None
        if inst is not None:  # under the lock: after a Safe state or a read still under way
            BackgroundCall(self._locked(inst.close), lambda r, e: None, name="biafc-gui-close")
        self.bench_panel.set_connected(False)

    def connect_bench(self) -> None:
        """Open the bench's instruments on a worker thread, then show their snapshot."""
        if self.bench_file is None and self._bench_error is not None:
            self.log(f"cannot connect: the bench file is not valid: {self._bench_error}", "error")
            return
        if self.bench_file is None or self._busy_connect or self.running:
            return
        bf = self.bench_file
        seed = bf.bench.simulation.seed if bf.bench.simulation is not None else None
        self._disconnect()
        self._busy_connect = True
        self.bench_panel.set_connected(False, busy=True)
        self._bench_status(f"{bf.bench.name}: connecting…")
        assembler = self._assembler
        unsafe = self._unsafe_mark is not None
        channels = sorted(set(bf.bench.direction_channel.values()))

        def work() -> tuple[Any, dict[str, Any], list[str] | None]:
            inst = assembler(bf, seed)
            # after an UNSAFE end: what the instruments say now, read back (nothing switched)
            return inst, inst.snapshot(), _not_confirmed_off(inst, channels) if unsafe else None

        BackgroundCall(work, lambda r, e: self._connected(bf, r, e), name="biafc-gui-connect")

    def _connected(self, bf: Any, result: Any, err: BaseException | None) -> None:
        self._busy_connect = False
        if self._closed:  # the window closed while they connected: closed here, not kept
            if err is None:  # on a closed window (before, their ports and locks stayed open)
                try:
                    result[0].close()
                except Exception as exc:
                    logging.getLogger("biafc.gui").warning(
                        "closing the instruments connected after the window closed: %s", exc
                    )
            return
        if err is None and bf is not self.bench_file:  # connected to a bench file changed
            # since: closed (its ports and instrument locks were kept until the window closed,
            # and a run_protocol was refused "in use by" this window; a second reader)
            dropped = result[0]
            self._busy_connect = True  # no new Connect to the same ports before it is closed

            def closed(r: Any, e: BaseException | None) -> None:
                self._busy_connect = False

            BackgroundCall(dropped.close, closed, name="biafc-gui-close-dropped")
        if err is not None or bf is not self.bench_file:
            msg = f"connect failed: {err}" if err is not None else "bench changed"
            self._bench_status(f"✗ {msg}")
            self.bench_panel.set_connected(False)
            self.log(msg, "error")
            if self._pending_start is not None:  # the start it waited for does not happen
                self._pending_start = None
                self.run_panel.set_state("idle")
            self.connected.emit(False)
            return
        inst, snap, not_off = result
        self.instruments = inst
        self.chain = inst.chain
        self.bench_panel.set_connected(True)
        if self._unsafe_mark is not None and not_off == []:  # read back: every output off
            self._clear_unsafe_mark(
                "the last run's UNSAFE is taken down: after Reconnect every output reads back "
                "off and the stage is at rest"
            )
        elif self._unsafe_mark is not None:  # before, Reconnect took it down unchecked
            self.log(
                "UNSAFE still holds after Reconnect: "
                + "; ".join(not_off or ["the outputs were not read back"]),
                "error",
            )
        self._bench_status(f"{bf.bench.name}: connected ({inst.backend})")
        self.bench_panel.show_snapshot(snap)
        self.views.show_chain(self.chain, self._f_in())
        self.log(f"connected to {bf.bench.name!r} ({inst.backend})")
        self.connected.emit(True)
        if self._pending_start is not None:
            (resume_path,) = self._pending_start
            self._pending_start = None
            self.start_run(resume_path)

    def refresh_snapshot(self) -> None:
        """Re-read every instrument's state (not during a run: the engine owns them then)."""
        if self.instruments is None:
            return
        if self.running:
            self.log("instrument state is refreshed after the run", "warning")
            return
        inst = self.instruments
        what = "reading the instruments' state"
        self._hold_instruments(what)

        def done(snap: Any, err: BaseException | None) -> None:
            self._release_instruments(what)
            if inst is not self.instruments:
                return
            if err is None:
                self.bench_panel.show_snapshot(snap)
                return
            # before, a failed read left the last state shown, and said nothing
            line = f"instrument state not read: {str(err).splitlines()[0] if str(err) else err!r}"
            self.bench_panel.tree.clear()
            self._bench_status(f"✗ {line}", "QLabel { color: #b00000; }")
            self.log(line, "error")

        BackgroundCall(self._locked(inst.snapshot), done, name="biafc-gui-snapshot")

    def safe_state(self) -> None:
        """During a run: abort (the engine puts every instrument in its safe state).
        Otherwise the run's own path (:mod:`daq.engine.safe_state`): outputs off, every
        instrument's ``safe_state()``, the outputs read back and the stage asked whether it
        came to rest; what is not confirmed is logged as what to switch off by hand. The button
        is disabled meanwhile (the stage may take seconds to come to rest)."""
        if self.running:
            self.abort("safe state requested")
            return
        inst = self.instruments
        if inst is None:
            return
        channels = sorted(set(self.bench_file.bench.direction_channel.values()))
        self.bench_panel.safe_button.setEnabled(False)
        self._hold_instruments("the Safe state")

        def work() -> dict[str, Any]:
            from daq.engine.outcome import unsafe_instruction
            from daq.engine.safe_state import bring_to_safe_state

            found = bring_to_safe_state(inst, channels)
            said = [*found.problems]
            if found.unconfirmed:
                said.append(unsafe_instruction(found.unconfirmed))
            if said:
                raise RuntimeError("; ".join(said))
            snap: dict[str, Any] = inst.snapshot()
            return snap

        def done(snap: Any, err: BaseException | None) -> None:
            self._release_instruments("the Safe state")
            if inst is self.instruments:
                self.bench_panel.safe_button.setEnabled(True)
            if err is not None:
                self.log(f"safe state: {err}", "error")
                return
            if inst is not self.instruments:  # disconnected meanwhile: not this bench's state
                self.log("instruments in safe state (before the bench was disconnected)")
                return
            self.log("instruments in safe state")
            self._clear_unsafe_mark()  # confirmed now: the last run's UNSAFE no longer holds
            self.bench_panel.show_snapshot(snap)

        BackgroundCall(self._locked(work), done, name="biafc-gui-safe")

    # -- protocol --------------------------------------------------------------------------
    def _ask_protocol(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Open protocol", "protocols", "Protocol files (*.yaml)"
        )
        if path:
            self.load_protocol(path)

    def load_protocol(self, path: str | Path) -> bool:
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8")
        except OSError as exc:
            self.protocol_panel.show_error(f"{p}: {exc.strerror or exc}")
            self.log(f"{p}: {exc}", "error")
            return False
        self.protocol_path = p
        self.protocol_panel.path_edit.setText(shown_path(p))
        self.protocol_panel.set_text(text)
        self.protocol_panel.validate_now()
        self.log(f"protocol {p.name} opened")
        return True

    def _validate_text(self, text: str) -> None:
        """Validate the editor's text against the schema and the bench's limits."""
        from daq.request import RequestError, validate_request
        from protocols.schema import parse_protocol
        from protocols.yamlfile import ConfigError

        source = self.protocol_path.name if self.protocol_path else "<protocol>"
        if self.bench_file is None and self._bench_error is not None:
            # nothing to check it against nor run it on: the bench file's error, not "valid"
            self.protocol_file, self.plan = None, None
            self.protocol_panel.show_error(f"no bench to run on: {self._bench_error}")
            self._set_startable(False)
            return
        try:
            pf = parse_protocol(text, source)
            proto = pf.protocol
            plan = None
            if self.bench_file is not None:  # the one validation of run_protocol, as typed
                plan = validate_request(pf, self.bench_file, check_output=False).plan
        except (ConfigError, RequestError) as exc:
            self.protocol_file, self.plan = None, None
            self.protocol_panel.show_error(str(exc))
            self._set_startable(False)
            return
        except Exception as exc:  # a schema corner the validators did not word
            self.protocol_file, self.plan = None, None
            self.protocol_panel.show_error(f"{source}: {type(exc).__name__}: {exc}")
            self._set_startable(False)
            return
        self.protocol_file, self.plan = pf, plan
        self._set_startable(True)
        summary = f"{proto.name}: valid"
        if plan is not None:
            summary += f", {plan.n_points} points, estimated {format_duration(plan.estimated_s)}"
        self.protocol_panel.show_ok(summary, _protocol_fields(proto, plan))
        if self.chain is not None:
            self.views.show_chain(self.chain, self._f_in())

    def _set_startable(self, ok: bool) -> None:
        """Start and Dry run only with a valid protocol (they only logged a refusal before)."""
        self.run_panel.set_startable(ok)
        self.protocol_panel.dry_button.setEnabled(ok and not self.run_panel.active)

    def _f_in(self, pf: Any = None) -> float | None:
        """The input frequency (Hz) the bands view marks: of protocol ``pf`` (default: the
        editor's), its first direction's."""
        pf = pf if pf is not None else self.protocol_file
        if pf is None:
            return None
        burst = pf.protocol.burst
        for d in ("ltr", "rtl"):
            if d in burst:
                return float(burst[d].f_center)
        return None

    def save_protocol(self) -> None:
        path = self.protocol_path
        if path is None:
            name, _ = QFileDialog.getSaveFileName(self, "Save protocol", "", "*.yaml")
            if not name:
                return
            path = Path(name)
        try:
            path.write_text(self.protocol_panel.editor.toPlainText(), encoding="utf-8")
        except OSError as exc:
            self.log(f"saving {path}: {exc}", "error")
            return
        self.protocol_path = path
        self.protocol_panel.path_edit.setText(shown_path(path))
        invalid = "" if self.protocol_panel.valid else " (INVALID)"
        self.log(f"protocol saved to {shown_path(path)}{invalid}")

    def dry_run(self) -> None:
        """Validate and report point count, ETA and output path; nothing moves."""
        if self.run_panel.active:  # the button is disabled meanwhile; a call from code
            self.log("dry run: a run is active; try again after it ends", "warning")
            return
        self.protocol_panel.validate_now()
        if self.protocol_file is None or self.plan is None:
            self.log("dry run: the protocol is not valid (see the protocol panel)", "error")
            return
        out = self._output_path()
        from daq.request import RequestError, validate_request

        try:  # the output too, as run_protocol --dry-run checks it (a complete run, no folder)
            out = validate_request(self.protocol_file, self.bench_file, out=out).out
        except RequestError as exc:
            self.log(f"dry run: refused: {exc}", "error")
            return
        self.log(
            f"dry run: {self.plan.n_points} points, estimated "
            f"{format_duration(self.plan.estimated_s)} ({self.plan.estimated_s:.1f} s); "
            f"output {shown_path(out)}{homing_note(self.bench_file)}"
        )

    # -- run -------------------------------------------------------------------------------
    def _output_path(self) -> Path:
        text = self.run_panel.out_edit.text().strip()
        if text:
            return Path(text)
        path: Path = self.protocol_file.protocol.output_path()
        return path

    def _ask_resume_file(self) -> None:
        if self.bench_file is None and self._bench_error is not None:  # before the dialog
            self.log(f"cannot resume: the bench file is not valid: {self._bench_error}", "error")
            return
        path, _ = QFileDialog.getOpenFileName(self, "Resume run file", "runs", "Run files (*.h5)")
        if path:
            self.start_run(Path(path))

    def start_run(
        self, resume_path: Path | None = None, prefill: LiveData | bool | None = None
    ) -> bool:
        """Start the protocol (or continue ``resume_path``); connects the bench first if
        needed. Returns False when it cannot start (the reason is logged). A resumed run's
        views start from the points already in its file (``prefill``: read on a worker thread
        first; ``False``: the read failed, the views start empty)."""
        from daq.engine import RunEngine
        from daq.request import RequestError, validate_request

        if self.running:
            return False
        if not isinstance(resume_path, Path):
            resume_path = None  # a clicked() bool
        if self.bench_file is None and self._bench_error is not None:
            self.log(f"cannot start: the bench file is not valid: {self._bench_error}", "error")
            self.run_panel.set_state("idle")
            return False
        if self._busy:  # the buttons are disabled meanwhile; a call from code is refused
            self.log(f"cannot start yet: {self._busy[0]} is still working on the instruments",
                     "warning")  # fmt: skip
            self.run_panel.set_state("idle")  # a start under way (a file read) ends here
            return False
        resume = resume_path is not None
        if not resume:  # a resumed run is the file's protocol, whatever the editor holds
            self.protocol_panel.validate_now()
            if self.protocol_file is None or self.plan is None:
                self.log(
                    "cannot start: the protocol is not valid (see the protocol panel)", "error"
                )
                return False
        try:  # the whole request, output and resume file included, before connecting
            req = validate_request(
                None if resume else self.protocol_file,  # resume: the file's, as run_protocol
                self.bench_file,
                out=None if resume else self._output_path(),
                resume=resume_path,
            )
        except RequestError as exc:  # refused before anything moved, as run_protocol's exit 2
            self.log(f"cannot start: {exc}", "error")
            self.run_panel.set_state("idle")
            self.run_panel.where_label.setText(in_window_words(f"run refused: {exc}"))
            self.run_panel.where_label.setStyleSheet("QLabel { color: #b00000; }")
            return False
        if self.instruments is None:
            self._pending_start = (resume_path,)
            self.run_panel.set_state("starting")
            self.connect_bench()
            return True
        if resume and prefill is None:  # the points already in the file, off the GUI thread
            from protocols.runfile import read_run

            assert resume_path is not None
            path = resume_path

            def read() -> LiveData:
                return LiveData.from_run(read_run(path))

            def then(live: Any, err: BaseException | None) -> None:
                if self._prefilling != path:  # aborted (or closed) while the file was read
                    return
                self._prefilling = None
                if err is not None:
                    self.log(f"{shown_path(path)}: its points are not shown ({err})", "warning")
                self.start_run(path, prefill=live if err is None else False)

            self._prefilling = path
            self.run_panel.set_state("starting")
            BackgroundCall(read, then, name="biafc-gui-prefill")
            return True
        bf, out, seed, pf = self.bench_file, req.out, req.seed, req.protocol
        try:
            engine = RunEngine(pf, bf, self.instruments, out, resume=resume, seed=seed)
        except Exception as exc:
            self.log(f"cannot start: {exc}", "error")
            self.run_panel.set_state("idle")
            return False
        if isinstance(prefill, LiveData):  # before, a resumed run's maps began empty
            self.live = prefill
        else:
            self.live = LiveData.for_plan(engine.plan, pf.protocol, self.chain)
        self.views.show_chain(self.chain, self._f_in(pf))
        self._set_model_for_bench(bf, pf)
        adapter = EngineEventAdapter(self)
        adapter.events_ready.connect(self._on_events)
        engine.subscribe(adapter)
        self.engine, self.adapter, self.run_path = engine, adapter, out
        self.setWindowTitle(f"biafc-lab — {out.name}")  # not a file browsed before the run
        self._run_open = True
        self.last_result = None
        self.run_panel.progress.setMaximum(engine.plan.n_points)
        self.run_panel.progress.setValue(self.live.n_points)  # a resumed run's points: done
        self.run_panel.set_state("running")
        self.run_panel.where_label.setStyleSheet("")  # a refusal's red, before this run
        # an earlier run's UNSAFE stays up through this one: only its end, reading every output
        # back off and the stage at rest, takes it down (:meth:`_finished`); before, Start took
        # it down unchecked
        from daq.logsetup import detach, hold_run_log

        detach(getattr(self, "_run_log", None))
        # opened once the run file is this window's (a run refused at its lock wrote into the
        # other process's RUN.log), by the engine
        held = hold_run_log(out)
        engine.on_file_locked = held.open_file
        self._run_log: logging.Handler | None = held
        self.log(f"{'resuming' if resume else 'starting'} run -> {shown_path(out)}")
        if bf.bench.simulation is not None:  # said now, before homing, when nothing is on disk
            from sim_backend.dem.kernel_cache import announce_if_cold

            announce_if_cold()
        engine.start()
        return True

    def pause(self) -> None:
        if self.engine is not None:
            self.engine.pause()

    def resume(self) -> None:
        if self.engine is not None:
            self.engine.resume()

    def abort(self, reason: str = "aborted by the user") -> None:
        if not isinstance(reason, str):
            reason = "aborted by the user"
        if not self.running and (self._pending_start is not None or self._prefilling):
            # still starting (the bench connecting, a resumed file being read): the start
            # is cancelled, as run_protocol's Ctrl-C while it connects; it went ahead before
            self._pending_start = self._prefilling = None
            self.run_panel.set_state("idle")
            self.run_panel.where_label.setText("start cancelled: nothing was switched on")
            self.log(f"start cancelled ({reason}): nothing was switched on", "warning")
            return
        if self.engine is not None and self.running:
            self.log(f"aborting: {reason}", "warning")
            self.engine.abort(reason)

    def console_closed(self, what: str, bound_s: float = CLOSE_BOUND_S) -> None:
        """Windows' console handler thread, not the window's (:mod:`daq.cli.console_close`):
        the console the window was started from is closing, and Windows ends the process when
        this returns. A run is aborted, and this waits for its safe state and file, at most
        ``bound_s`` s. Touches no widget: the engine's abort and wait are thread-safe."""
        self._abort_and_wait(f"interrupted: {what}", bound_s)

    def display_lost(self, message: str, bound_s: float = DISPLAY_LOST_BOUND_S) -> None:
        """The display is gone (:mod:`daq.gui.display_lost`; Qt's warning ``message``), and Qt
        ends the process when this returns. A run is aborted, and this waits for its safe state
        and file, at most ``bound_s`` s. Touches no widget: there is no display to draw on."""
        self._abort_and_wait(f"interrupted: the display went away ({message.strip()})", bound_s)

    def _abort_and_wait(self, reason: str, bound_s: float) -> None:
        engine = self.engine
        if engine is None or not self.running:
            return
        logging.getLogger("biafc.gui").error("%s: aborting the run", reason)
        engine.abort(reason)
        engine.wait(bound_s)

    def _on_events(self) -> None:
        """GUI thread: handle a batch of engine events."""
        from daq.engine import EventKind

        sender = self.sender()
        adapter = sender if isinstance(sender, EngineEventAdapter) else self.adapter
        if adapter is None:
            return
        for ev in adapter.drain():
            k, d = ev.kind, ev.data
            if k == EventKind.POINT_DONE:
                try:
                    self.live.add_point(d)
                except Exception as exc:
                    self.log(f"live view: {exc}", "warning")
                self._dirty = True
            elif k == EventKind.POINT_FAILED:  # marked in the maps, not left as "not yet"
                try:
                    self.live.add_failed(d)
                except Exception as exc:
                    self.log(f"live view: {exc}", "warning")
                self._dirty = True
            elif k == EventKind.PROGRESS:
                self.run_panel.show_progress(d)
                if self.engine is not None and self.engine.state.value == "paused":
                    self.run_panel.where_label.setText(PAUSED_LINE)  # the point in flight
            # the engine records its own events in the run's log and file: shown here only
            elif k == EventKind.STATE_CHANGED:
                self.run_panel.set_state(str(d["state"]))
                self.log(f"run {d['state']}", record=False)
                if d["state"] == "paused":  # the line kept the last ETA, as if running
                    self.run_panel.where_label.setText(PAUSED_LINE)
                elif d["state"] == "running" and self.run_panel.where_label.text() == PAUSED_LINE:
                    self.run_panel.where_label.setText("running again")
            elif k == EventKind.RUN_STARTED:
                self.log(
                    f"run {shown_path(d['path'])}: {d['n_todo']} of {d['n_points']} points to "
                    "measure "
                    f"(estimated {format_duration(d['estimated_s'])})",
                    record=False,
                )
            elif k == EventKind.WARNING:  # a failed point's line too (POINT_FAILED repeats it)
                self.log(ev.message, str(d.get("level", "warning")), record=False)
            elif k == EventKind.STATUS:
                self.run_panel.where_label.setText(str(d["text"]))
                self.log(str(d["text"]), record=False)
            elif k == EventKind.FINISHED:
                self._finished(d)

    def _finished(self, d: dict[str, Any]) -> None:
        from daq.engine.outcome import final_line

        status = str(d["status"])
        self._run_open = False
        self.last_result = self.engine.result if self.engine is not None else None
        self.run_panel.set_state(status)
        level = "info" if status == "complete" else "error"
        if self.last_result is not None:
            line = final_line(self.last_result).replace(
                str(self.last_result.path), shown_path(d["path"])
            )
        else:
            reason = f": {d['reason']}" if d.get("reason") else ""
            line = f"run {status}{reason}"
        if (
            status != "unsafe"
            and self._unsafe_mark is not None
            and d.get("safe_state_s") is not None
        ):
            # this run's end read every output back off and the stage at rest: said before the
            # run's last line, which stays the last of the window's log and of the run's log
            # file (before, this note came after it there)
            self._clear_unsafe_mark(
                "the earlier run's UNSAFE is taken down: this run's end read every output back "
                "off and the stage at rest"
            )
        self.log(line, level)
        self.run_panel.where_label.setText(in_window_words(line))
        # unsafe: red and bold until the next run, and in the status bar (no modal dialog: the
        # person may be at the bench, the text stays until read)
        style = {"unsafe": "color: #b00000; font-weight: bold;", "complete": ""}.get(
            status, "color: #b00000;"
        )
        self.run_panel.where_label.setStyleSheet(f"QLabel {{ {style} }}" if style else "")
        if status == "unsafe":
            self.statusBar().showMessage(line)
            from daq.engine.outcome import unsafe_instruction

            unconfirmed = list(d.get("unconfirmed") or [])
            # what to switch off named here: a next run replaces the run's last line
            self._unsafe_bench = _bench_identity(self.bench_file)
            self._unsafe_mark = f"✗ UNSAFE: the safe state of {Path(d['path']).name} was not " + (
                f"confirmed; {unsafe_instruction(unconfirmed)}"
                if unconfirmed
                else "confirmed; switch off by hand what the run's last line names"
            )
            self._bench_status("")
        if self.last_result is not None:  # the process's status is the last run's, as
            from daq.engine.outcome import exit_code  # run_protocol's (0 when it completed)

            self.exit_status = int(exit_code(self.last_result))
        self._redraw()
        self.refresh_snapshot()
        from daq.logsetup import detach

        detach(getattr(self, "_run_log", None))
        self._run_log = None
        self.run_finished.emit(status)
        if self._open_after_run is not None:  # promised when it was opened during the run
            (path, on_done), self._open_after_run = self._open_after_run, None
            self.open_run_file(path, on_done)

    def _show_compile(self, phase: str, elapsed_s: float, folder: str, cold: bool) -> None:
        """The command line's compile notice, in the log and the run panel's line."""
        from daq.cli.compile_notice import doing, ready_line, start_line

        if phase == "start":
            self.log(start_line(folder, cold))
        if phase in ("start", "tick"):
            self.run_panel.where_label.setText(
                f"{doing(cold)} the DEM kernel (once per installation) ... {elapsed_s:.0f} s"
            )
        elif phase == "done":
            self.log(ready_line(elapsed_s))
            self.run_panel.where_label.setText(ready_line(elapsed_s))

    def _bench_status(self, text: str, style: str = "") -> None:
        """The bench panel's status line: ``text``, below the "UNSAFE" of an earlier run while
        that holds (before, Connect's "connecting…", its failure or its success replaced it)."""
        label = self.bench_panel.status_label
        if self._unsafe_mark is None:
            label.setStyleSheet(style)
            label.setText(text)
            return
        label.setStyleSheet("QLabel { color: #b00000; font-weight: bold; }")
        label.setText(f"{self._unsafe_mark}\n{text}" if text else self._unsafe_mark)

    def _clear_unsafe_mark(self, said: str = "") -> None:
        """Take down the bench panel's "UNSAFE" of an earlier run: once a Safe state, the
        outputs read back after a Reconnect, or a later run's end confirmed every output off
        and the stage at rest, on the bench that run ran on (``said``: logged when it goes).
        Before, a Reconnect, and the start of a run, took it down unchecked, a generator output
        reported on; and another bench's read-back took it down too (a reviewer)."""
        if self._unsafe_mark is None:
            return
        if (
            self._unsafe_bench is not None
            and _bench_identity(self.bench_file) != self._unsafe_bench
        ):
            self.log(
                "UNSAFE still holds: that read-back was of other instruments than the UNSAFE "
                "run's (its generator and stage); open a bench file naming them and confirm "
                "their safe state",
                "error",
            )
            return
        if said:
            self.log(said)
        self._unsafe_mark = None
        self._unsafe_bench = None
        name = self.bench_file.bench.name if self.bench_file is not None else "bench"
        backend = getattr(self.instruments, "backend", "")
        self._bench_status(f"{name}: connected ({backend})" if backend else name)

    def _redraw_if_dirty(self) -> None:
        interval = self._pace.tick()
        if interval != self._redraw_timer.interval():
            self._redraw_timer.setInterval(interval)
        if self._dirty:
            self._redraw()

    def _redraw(self) -> None:
        self._dirty = False
        self.views.redraw(self.live)

    # -- run files -------------------------------------------------------------------------
    def _ask_run_file(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open run file", "runs", "Run files (*.h5)")
        if path:
            self.open_run_file(path)

    def open_run_file(
        self, path: str | Path, on_done: Callable[[bool], None] | None = None
    ) -> None:
        """Read a run file on a worker thread and browse it with the live views."""
        from protocols.runfile import read_run

        p = Path(path)

        def work() -> tuple[Any, LiveData]:
            run = read_run(p)
            return run, LiveData.from_run(run)

        def done(result: Any, err: BaseException | None) -> None:
            if err is not None:
                text = str(err)  # most errors name the file already
                self.log(text if str(p) in text else f"{p}: {text}", "error")
                if on_done:
                    on_done(False)
                return
            run, live = result
            if self.running:  # read again then: it may be the run's own file
                self._open_after_run = (p, on_done)
                self.log(f"a run is active: {p.name} is shown after it ends", "warning")
                return
            self.live = live
            self.run_path = p
            self._set_model_for_run(run)
            f_in = next(iter(live.scans.values())).f_center_Hz if live.scans else None
            self.views.show_chain(live.chain, f_in)
            self._redraw()
            failed = f", {live.n_failed} failed" if live.n_failed else ""
            self.log(
                f"opened {p.name}: status {run.status}, {live.n_points} points measured{failed}"
            )
            self.setWindowTitle(f"biafc-lab — {p.name}")
            if on_done:
                on_done(True)

        BackgroundCall(work, done, name="biafc-gui-read")

    def _ask_export(self) -> None:
        path = self.run_path
        if path is None:
            name, _ = QFileDialog.getOpenFileName(self, "Run file", "runs", "Run files (*.h5)")
            if not name:
                return
            path = Path(name)
        self.export_figures(path)

    def export_figures(
        self,
        path: str | Path,
        out_dir: str | Path | None = None,
        on_done: Callable[[bool], None] | None = None,
    ) -> None:
        """Write the paper's figures of a run file (``biafc figures``) on a worker thread."""
        from analysis.report import write_figures
        from protocols.runfile import read_run

        p = Path(path)
        out = Path(out_dir) if out_dir is not None else p.with_name(p.stem + "_figures")
        if self.running and p == self.run_path:
            self.log("export: the run is still being written", "warning")
            return

        def done(result: Any, err: BaseException | None) -> None:
            if err is not None:
                self.log(f"export figures: {err}", "error")
            else:
                self.log(f"figures of {p.name} written to {shown_path(out)}")
            if on_done:
                on_done(err is None)

        BackgroundCall(lambda: write_figures(read_run(p), out), done, name="biafc-gui-export")

    # -- closing ---------------------------------------------------------------------------
    def confirm_close(self) -> bool:
        """Ask whether to abort the active run and close (tests replace this)."""
        answer = QMessageBox.question(
            self,
            "Run in progress",
            "A run is in progress. Abort it (instruments go to their safe state) and close?",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
            QMessageBox.StandardButton.No,
        )
        return answer == QMessageBox.StandardButton.Yes

    def stop_signal(self, signum: int) -> None:
        """SIGTERM, SIGHUP or Ctrl-C (:mod:`daq.gui.stop_signals`): close as Close does, without
        asking. A run is aborted ("interrupted by SIGTERM") and the process's exit status is the
        run's (Ctrl-C's 130, as ``run_protocol``'s); with no run, 128 + the signal's number."""
        name = signal.Signals(signum).name
        if self._closing:  # a second one: the close under way waits for the safe state
            self.log(f"{name} received: still closing, waiting for the safe state", "warning")
            return
        self._stop_signal = signum
        self.log(f"{name} received: closing the window", "warning")
        if self._asking_close:  # Close's question is open: Qt refuses a close inside that one
            modal = QApplication.activeModalWidget()
            if modal is not None:
                modal.close()  # the question returns, and that close goes on as signalled
            return
        self.close()

    def closeEvent(self, event: QCloseEvent) -> None:
        signum = self._stop_signal
        self._open_after_run = None  # no run file waiting to be shown (before the ended run
        # is handled: that would start reading it while the window closes; a reviewer)
        self._handle_ended_run()  # a run that ended unhandled: its outcome, not a question
        self._pending_start = self._prefilling = None  # a start under way does not go ahead
        if not self.running and signum is not None and self.exit_status != 3:
            self.exit_status = 128 + signum  # idle: the signal's own (an unsafe end's 3 stays)
        if self.running:
            if signum is None:
                self._asking_close = True
                try:
                    yes = self.confirm_close()
                finally:
                    self._asking_close = False
                signum = self._stop_signal  # a signal while the question was open: it wins
                if signum is None and not yes:
                    event.ignore()
                    return
            self._closing = True
            self.abort(  # no effect on a run that ended while the question was open
                "window closed during the run"
                if signum is None
                else f"interrupted by {signal.Signals(signum).name}"
            )
            deadline = time.monotonic() + CLOSE_WAIT_S
            while self.engine.wait(0.05) is None and time.monotonic() < deadline:
                QApplication.processEvents()
            QApplication.processEvents()
            if self.adapter is not None:
                self._on_events()
            from daq.engine.outcome import ExitCode, exit_code

            if self.engine.result is not None:  # the window's exit status is the run's
                sigint = signum == signal.SIGINT
                self.exit_status = int(exit_code(self.engine.result, sigint=sigint))
            else:  # the run did not end: nothing confirmed its safe state
                self.log(
                    f"the run did not end within {CLOSE_WAIT_S:g} s of the abort: its safe state "
                    "is not confirmed; switch the generator's outputs off by hand",
                    "error",
                )
                self.exit_status = int(ExitCode.UNSAFE)
        self._finish_close(event)

    def _finish_close(self, event: QCloseEvent) -> None:
        self._redraw_timer.stop()
        from sim_backend.dem import kernel_cache

        if kernel_cache._REPORTER is self._report:  # not another window's, opened after this
            kernel_cache.set_compile_reporter(self._previous_reporter)
        if self.instruments is not None:
            # after a Safe state (or a read) still under way: closing the transports under it
            # cut it off ("transport closed, cannot send 'OUTP1?'", a second reader)
            if self._instrument_lock.acquire(timeout=CLOSE_WAIT_S):
                try:
                    self.instruments.close()
                except Exception:
                    pass
                finally:
                    self._instrument_lock.release()
            else:
                self.log(
                    f"the Safe state did not end within {CLOSE_WAIT_S:g} s: it is not "
                    "confirmed; switch the generator's outputs off by hand",
                    "error",
                )
                self.exit_status = 3
            self.instruments = None
        # let the workers that just finished (the read after the run, now unblocked by the
        # lock) emit their result while Qt is still alive: one emitting during the
        # interpreter's exit crashed the process (exit -11 after a stop signal mid-run)
        for call in list(BackgroundCall._alive):
            call.worker.join(timeout=5.0)
        self._closed = True
        if self._busy_connect:  # a connect ended meanwhile: its instruments closed now, not
            QApplication.processEvents()  # left to an event loop that may not turn again
        event.accept()


def _not_confirmed_off(instruments: Any, channels: list[int]) -> list[str]:
    """What of the bench is not confirmed safe by reading it back, nothing switched: each of
    the generator's ``channels`` whose output reads on or cannot be read, a stage that moves or
    does not say (an empty list: every output off, the stage at rest)."""
    from daq.engine.safe_state import generator_name

    gen = instruments.generator
    said: list[str] = []
    for ch in channels:
        try:
            if gen.output_state(ch):
                said.append(f"{generator_name(gen)} output {ch} is ON")
        except Exception as exc:
            said.append(f"{generator_name(gen)} output {ch}: cannot read it back ({_first(exc)})")
    try:
        if instruments.stage.is_moving():
            said.append("stage controller: the axis moves")
    except Exception as exc:
        said.append(f"stage: cannot read whether it moves ({_first(exc)})")
    return said


def _bench_identity(bench_file: Any) -> tuple[str, ...] | None:
    """What a safe state is of: the simulated bench, or a lab bench's generator and stage by
    their addresses, each spelling that certainly names the same resource one key
    (:func:`instruments.transport.same_resource_key`: ``tcpip::h::instr`` is
    ``TCPIP0::h::inst0::INSTR``, ``com3`` ``COM3``; no name lookup in the window's thread).
    Two addresses that may or may not be one instrument stay two: the mark stays up (before,
    the address as written, upper-cased, which kept it up for the same generator re-typed,
    and took it down for ``/dev/ttyusb0`` after ``/dev/ttyUSB0``). A bench file edited in a
    comment, or renamed, names the same instruments (a reviewer: the mark had been tied to
    the file's text)."""
    from instruments.transport import same_resource_key

    if bench_file is None:
        return None
    b = bench_file.bench
    if b.simulated:  # (a lab bench file may keep a simulation block: it is not simulated)
        return ("simulated",)
    return ("lab", same_resource_key(b.generator.resource), same_resource_key(b.stage.resource))


def _first(exc: BaseException) -> str:
    """An exception's first line (the window's log holds one line a message)."""
    text = str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


#: the run panel's line while a run is paused
PAUSED_LINE = "paused (after the point in flight): Resume to go on"

#: how long closing the window waits for an aborted run's safe state and file (s)
CLOSE_WAIT_S = 60.0


def _protocol_fields(proto: Any, plan: Any) -> dict[str, str]:
    """The protocol's resolved fields, SI with units, for the protocol panel."""
    acq = proto.acquisition
    out: dict[str, str] = {"name": proto.name, "directions": ", ".join(proto.direction_list)}
    for d, spec in proto.burst.items():
        b = spec.burst()
        shape = f"{b.cycles:g} cycles" if b.cycles is not None else f"width {b.width_s:g} s"
        out[f"burst.{d}"] = (
            f"f_center {b.f_center_Hz:g} Hz, {shape} (sigma_f {b.sigma_f_Hz:.4g} Hz)"
        )
    if plan is not None:
        unit = plan.amplitude_units
        amps = ", ".join(f"{a:.4g}" for a in plan.amplitudes)
        out["amplitudes"] = f"[{amps}] {'m' if unit == 'm' else 'Vpp'}"
        out["cylinders"] = ", ".join(str(int(c)) for c in plan.cylinders)
        out["points"] = f"{plan.n_points}"
        out["estimated"] = f"{plan.estimated_s:.1f} s"
    out["averages"] = str(proto.averages)
    out["acquisition"] = f"rate {acq.rate:g} S/s, duration {acq.duration:g} s"
    out["settle"] = f"{proto.settle:g} s"
    out["order"] = " > ".join(proto.order)
    out["output"] = proto.output
    out["on_point_failure"] = f"{proto.on_point_failure}, retries {proto.retries}"
    return out
