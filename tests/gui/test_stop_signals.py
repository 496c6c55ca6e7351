"""SIGTERM, SIGHUP and Ctrl-C reaching the bench window (:mod:`daq.gui.stop_signals`). Before,
SIGTERM and SIGHUP (a ``kill``, the ``ssh`` session closed) ended the process by their default
action mid-run: exit 143 or 129, the file ``running`` with its lock, no safe state, the log cut
short; Ctrl-C in the terminal did nothing while the window waited. Now each closes the window
as Close does, without asking: the run is aborted, its safe state and file are waited for, and
the process ends with the run's exit status (1; Ctrl-C 130), or 128 + the signal with no run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from protocols.runfile import read_run

from .conftest import RUN_AT_ONCE_SCRIPT, running_window, wait_first_point, wait_until

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _window(out: Path, script: str = RUN_AT_ONCE_SCRIPT) -> subprocess.Popen[str]:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-c", script, str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


@pytest.mark.parametrize(("sig", "status"), [("SIGTERM", 1), ("SIGHUP", 1), ("SIGINT", 130)])
def test_a_stop_signal_mid_run_aborts_it_safely_and_exits_with_its_status(
    tmp_path: Path, sig: str, status: int
) -> None:
    out = tmp_path / "s.h5"
    proc = _window(out)
    try:
        wait_first_point(proc, out)
        proc.send_signal(getattr(signal, sig))
        rc = proc.wait(60)
        _, stderr = proc.communicate()
    finally:
        proc.kill()
    assert rc == status, stderr[-2000:]
    run = read_run(out)
    assert run.status == "aborted", stderr[-2000:]
    log = out.with_suffix(".log").read_text(encoding="utf-8")
    assert f"run aborted: interrupted by {sig}" in log
    assert "safe state confirmed" in log
    assert not (tmp_path / "s.h5.lock").exists()


_IDLE = r"""
import sys
import daq.gui.main_window as main_window
from daq.gui import app
from tests.gui.conftest import SMOKE

class Window(main_window.MainWindow):
    def __init__(self, bench, protocol):
        super().__init__(bench, SMOKE)
    def show(self):
        super().show()
        print("shown", flush=True)

main_window.MainWindow = Window
ns = app.argparse.Namespace(bench=None, protocol=None, run=None, connect=False, verbose=0,
                            quiet=False)
sys.exit(app.run_window(ns))
"""


def test_sigterm_with_no_run_closes_the_window_at_once(tmp_path: Path) -> None:
    proc = _window(tmp_path / "unused.h5", _IDLE)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "shown"
        time.sleep(0.5)  # the event loop waiting: no Python runs until the signal wakes it
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(30)
        took = time.monotonic() - t0
    finally:
        proc.kill()
    assert rc == 128 + signal.SIGTERM
    assert took < 10


def test_a_second_signal_while_closing_waits_for_the_same_safe_state(
    qtbot: Any, tmp_path: Path
) -> None:
    win = running_window(qtbot, tmp_path / "twice.h5", read_sleep_s=0.5)
    engine_wait, seconds = win.engine.wait, []

    def wait(timeout_s: float) -> Any:  # the second signal comes during the first's wait
        if not seconds:
            seconds.append(True)
            win.stop_signal(signal.SIGTERM)
        return engine_wait(timeout_s)

    win.engine.wait = wait
    win.stop_signal(signal.SIGTERM)
    assert win.exit_status == 1
    assert read_run(tmp_path / "twice.h5").status == "aborted"
    shown = "\n".join(win.log_view.lines)
    assert "SIGTERM received: still closing, waiting for the safe state" in shown
    assert shown.count("SIGTERM received: closing the window") == 1


def test_a_run_that_does_not_end_after_the_abort_is_not_called_safe(
    qtbot: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Closing waits a bounded time for the aborted run; before, a run still going at the end
    of the wait closed the window with exit status 0, as if all were well."""
    import daq.gui.main_window as main_window

    win = running_window(qtbot, tmp_path / "slow.h5", read_sleep_s=3.0)
    monkeypatch.setattr(main_window, "CLOSE_WAIT_S", 0.2)
    engine = win.engine
    # mid-read: between two points the abort ends the run at once (under load the window
    # saw the first point while the engine was still before the second read: exit 1)
    wait_until(qtbot, engine.instruments.digitiser.reading.is_set, timeout_s=30)
    win.stop_signal(signal.SIGTERM)
    assert win.exit_status == 3  # unsafe: nothing confirmed the outputs off
    assert "its safe state is not confirmed" in "\n".join(win.log_view.lines)
    assert engine.wait(30) is not None  # the run does end, later


def test_a_signal_while_the_close_question_is_open_aborts_the_run(
    qtbot: Any, tmp_path: Path
) -> None:
    """Close's question on screen, then SIGTERM (a log-out): Qt refused the signal's close inside
    the open one, so the run went on and the process lived until SIGKILL; now the question is
    dismissed and that close goes on as the signal's."""
    from PySide6.QtCore import QTimer

    from daq.gui.main_window import MainWindow

    win = running_window(qtbot, tmp_path / "asked.h5", read_sleep_s=0.5)
    win.confirm_close = MainWindow.confirm_close.__get__(win)  # type: ignore[method-assign]
    QTimer.singleShot(300, lambda: win.stop_signal(signal.SIGTERM))  # the question is open
    win.close()
    assert not win.isVisible()
    assert win.exit_status == 1
    run = read_run(tmp_path / "asked.h5")
    assert run.status == "aborted"
    assert any("interrupted by SIGTERM" in m for _, _, m in run.log)


def test_a_run_that_ends_while_the_close_question_is_open_gives_its_status(
    qtbot: Any, tmp_path: Path
) -> None:
    """The run ended (here aborted) while Close's question was on screen, then the answer came:
    the window exited 0 whatever the run's end (an unsafe one too), where it had given the
    run's status (found by a second reader)."""
    win = running_window(qtbot, tmp_path / "ended.h5", read_sleep_s=0.2)
    engine = win.engine

    def question_while_the_run_ends() -> bool:
        engine.abort("ended while asking")
        assert engine.wait(30) is not None
        return True

    win.confirm_close = question_while_the_run_ends  # type: ignore[method-assign]
    win.close()
    assert not win.isVisible()
    assert engine.result.status == "aborted"
    assert win.exit_status == 1
