"""Fixtures of the GUI tests: the bench window on the simulated bench."""

from __future__ import annotations

import gc
import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from PySide6.QtCore import QElapsedTimer, QTimer

from daq.connect import connect_bench
from daq.gui.main_window import MainWindow, shown_path

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "protocols" / "smoke.yaml"


@pytest.fixture(autouse=True)
def _collect_qt_garbage_on_the_gui_thread() -> Iterator[None]:
    """Collect the cyclic garbage (closed windows, widgets in reference cycles) here, on the
    GUI thread, before and after every GUI test. Left for later, the collector ran it on
    whichever thread allocated next: a worker of the next test, whose ~QObject then waited for
    the GIL while holding Qt's mutex, and the GUI thread, deleting widgets, waited for that
    mutex (the full suite hung three times in test_window; gdb: gc_collect_main on the worker).
    A window also switches automatic collection to a GUI-thread timer (daq.gui.gui_gc): give
    it back after the test so the rest of the session collects."""
    from daq.gui import gui_gc

    gc.collect()
    yield
    gui_gc.uninstall()  # collects here, then automatic collection is back on


@pytest.fixture
def screenshots(tmp_path: Path) -> Path:
    """Where screenshots go: ``$BIAFC_SCREENSHOTS`` (e.g. ``docs/screenshots`` to refresh the
    docs' pictures), else a temporary folder so a test run leaves the tree untouched."""
    target = os.environ.get("BIAFC_SCREENSHOTS")
    out = Path(target) if target else tmp_path / "screenshots"
    out.mkdir(parents=True, exist_ok=True)
    return out


class SlowDigitiser:
    """The simulated bench's digitiser with ``read_sleep_s`` of wall time per read (the
    simulated bench takes no wall time), so a test can press buttons mid-run."""

    def __init__(self, inner: Any, read_sleep_s: float) -> None:
        self._inner = inner
        self._sleep = read_sleep_s
        #: set while a read sleeps (a test that needs the run mid-read waits for it)
        self.reading = threading.Event()

    def read(self) -> Any:
        self.reading.set()
        try:
            time.sleep(self._sleep)
        finally:
            self.reading.clear()
        return self._inner.read()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def make_assembler(read_sleep_s: float = 0.0) -> Callable[[Any, int | None], Any]:
    """The simulated bench, its digitiser slowed by ``read_sleep_s`` of wall time per read."""

    def sim(bf: Any, seed: int | None) -> Any:
        inst = connect_bench(bf, seed=seed)
        if read_sleep_s:
            inst.digitiser = SlowDigitiser(inst.digitiser, read_sleep_s)
        return inst

    return sim


def silent_generator(
    runs: int | None = None, read_sleep_s: float = 0.0
) -> Callable[[Any, int | None], Any]:
    """An assembler whose generator goes silent mid-run (after 3 acquisitions), so that the run
    ends UNSAFE: on its first ``runs`` connects (None: every one), a plain simulated bench after
    them; each record taking ``read_sleep_s`` longer."""
    calls: list[int] = []

    def bench(bf: Any, seed: int | None) -> Any:
        calls.append(1)
        faults = {"generator_silent": True, "after_acquisitions": 3}
        silent = runs is None or len(calls) <= runs
        inst = connect_bench(bf, seed=seed, faults=faults if silent else None)
        if read_sleep_s:
            inst.digitiser = SlowDigitiser(inst.digitiser, read_sleep_s)
        return inst

    return bench


def unsafe_window(qtbot: Any, out: Path, assembler: Callable[[Any, int | None], Any]) -> MainWindow:
    """The window, connected through ``assembler``, after a run into ``out`` that ended
    UNSAFE (asserted)."""
    win = MainWindow(None, SMOKE, assembler=assembler)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(out))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    return win


def _window_output(tmp_path: Path) -> Path:
    """The run file of :func:`window`: in the test's folder, or, when the screenshots go to the
    docs, ``runs/smoke_run.h5`` under the working folder (ignored by git), so that the pictures
    show a path that names no machine (they showed ``/tmp/pytest-of-root/...``)."""
    if not os.environ.get("BIAFC_SCREENSHOTS"):
        return tmp_path / "run.h5"
    out = Path("runs") / "smoke_run.h5"
    for old in (out, out.with_suffix(".log"), out.with_name(out.name + ".lock")):
        old.unlink(missing_ok=True)
    return out


@pytest.fixture
def window(qtbot: Any, tmp_path: Path) -> Iterator[MainWindow]:
    win = MainWindow(None, SMOKE, assembler=make_assembler(read_sleep_s=0.03))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.run_panel.out_edit.setText(shown_path(_window_output(tmp_path)))
    win.show()
    yield win
    if win.running:
        win.engine.abort("test teardown")
        win.engine.wait(30)


def connect(qtbot: Any, win: MainWindow) -> None:
    with qtbot.waitSignal(win.connected, timeout=60_000) as blocker:
        win.bench_panel.connect_button.click()
    assert blocker.args == [True], win.log_view.lines[-3:]


class StallProbe:
    """A 10 ms QTimer that records the longest gap between its ticks (ms): how long the event
    loop was blocked."""

    def __init__(self) -> None:
        self.timer = QTimer()
        self.timer.setInterval(10)
        self.clock = QElapsedTimer()
        self.gaps_ms: list[float] = []
        self.timer.timeout.connect(self._tick)

    def start(self) -> None:
        self.clock.start()
        self.timer.start()

    def pause(self) -> None:
        self.timer.stop()

    def _tick(self) -> None:
        self.gaps_ms.append(self.clock.restart())

    def stop(self) -> float:
        self.timer.stop()
        return max(self.gaps_ms) if self.gaps_ms else float("inf")


def wait_until(qtbot: Any, cond: Callable[[], bool], timeout_s: float = 60.0) -> None:
    t0 = time.monotonic()
    qtbot.waitUntil(cond, timeout=int(timeout_s * 1000))
    assert time.monotonic() - t0 <= timeout_s


def running_window(qtbot: Any, out: Path, read_sleep_s: float = 0.1) -> MainWindow:
    """A window on the slowed simulated bench whose run into ``out`` has measured a point."""
    win = MainWindow(None, SMOKE, assembler=make_assembler(read_sleep_s=read_sleep_s))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(out))
    connect(qtbot, win)
    win.run_panel.start_button.click()
    wait_until(qtbot, lambda: win.live.n_points >= 1)
    return win


class StubWindow:
    """What ``daq.gui.app.run_window`` asks of the window, doing nothing (tests of the app's
    own steps)."""

    exit_status = 0

    def __init__(self, *args: Any) -> None:
        pass

    def show(self) -> None:
        pass

    def console_closed(self, what: str) -> None:
        pass

    def display_lost(self, message: str) -> None:
        pass

    def stop_signal(self, signum: int) -> None:
        pass


def window_args() -> Any:
    """``biafc gui``'s parsed arguments with nothing given."""
    import argparse

    return argparse.Namespace(bench=None, protocol=None, run=None, connect=False, verbose=0,
                              quiet=False)  # fmt: skip


#: ``python -c`` script: the bench window on the slowed simulated bench (1 s a read), its run
#: into ``sys.argv[1]`` started at once, through ``daq.gui.app.run_window`` (the process as
#: ``biafc-gui`` makes it)
RUN_AT_ONCE_SCRIPT = r"""
import sys
from PySide6.QtCore import QTimer
import daq.gui.main_window as main_window
from daq.gui import app
from tests.gui.conftest import SMOKE, make_assembler

out = sys.argv[1]
Real = main_window.MainWindow

class Window(Real):  # the window with a slow simulated bench, its run started at once
    def __init__(self, bench, protocol):
        super().__init__(bench, SMOKE, assembler=make_assembler(read_sleep_s=1.0))
        self.confirm_close = lambda: True
        self.run_panel.out_edit.setText(out)
        self.connected.connect(lambda ok: QTimer.singleShot(0, self.run_panel.start_button.click))
        QTimer.singleShot(0, self.bench_panel.connect_button.click)

main_window.MainWindow = Window
ns = app.argparse.Namespace(bench=None, protocol=None, run=None, connect=False, verbose=0,
                            quiet=False)
sys.exit(app.run_window(ns))
"""


def wait_first_point(proc: Any, out: Path, timeout_s: float = 90.0) -> None:
    """Wait until the window process ``proc`` (of :data:`RUN_AT_ONCE_SCRIPT`) has measured a
    point into ``out``; it must not end before."""
    from protocols.runfile import PointState, read_run

    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        assert proc.poll() is None, proc.communicate()
        try:
            if (read_run(out).scans["ltr"].done == PointState.DONE).any():
                return
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.1)
    raise AssertionError(f"no point measured in {timeout_s:g} s")
