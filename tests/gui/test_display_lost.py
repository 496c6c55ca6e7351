"""The display going away under the bench window (``ssh -X`` dropped, the X server gone):
Qt warns "The X11 connection broke" and ends the process. Before, a run was cut off where it
stood (on Xvfb killed mid-run: exit 1, the file ``running`` with its lock, the log cut short,
no safe state); now the window aborts it and waits for its safe state first
(:mod:`daq.gui.display_lost`)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from PySide6.QtCore import qWarning

from daq.gui.display_lost import watch_display
from protocols.runfile import read_run

from .conftest import RUN_AT_ONCE_SCRIPT, running_window, wait_first_point

ROOT = Path(__file__).resolve().parents[2]
BROKE = "The X11 connection broke (error 1). Did the X11 server die?"


def test_the_watch_passes_messages_on_and_calls_back_on_a_broken_connection() -> None:
    from PySide6.QtCore import qInstallMessageHandler

    before: list[str] = []  # the handler in place before (Qt's own, or pytest-qt's here)
    outer = qInstallMessageHandler(lambda mode, context, message: before.append(message))
    lost: list[str] = []
    try:
        restore = watch_display(lost.append)
        qWarning("a warning of no consequence")
        assert lost == [] and before == ["a warning of no consequence"]
        qWarning(BROKE)
        assert lost == [BROKE] and before[-1] == BROKE  # passed on, then called back
        restore()
        qWarning(BROKE)
        assert lost == [BROKE] and len(before) == 3  # the previous handler is back
    finally:
        qInstallMessageHandler(outer)


def test_the_window_aborts_its_run_safely_when_the_display_is_lost(
    qtbot: Any, tmp_path: Path
) -> None:
    win = running_window(qtbot, tmp_path / "d.h5")
    engine = win.engine
    win.display_lost(BROKE)  # on the window's thread, as Qt's warning comes
    result = engine.result  # what there is when Qt ends the process
    assert result is not None and result.status == "aborted"
    assert result.safe_state_s is not None
    assert "the display went away" in result.reason
    run = read_run(tmp_path / "d.h5")
    assert run.status == "aborted"
    assert not (tmp_path / "d.h5.lock").exists()


def _xvfb(display: str) -> subprocess.Popen[bytes] | None:
    """An X server of its own on ``display``, or None where Xvfb or Qt's xcb plugin is
    missing."""
    if sys.platform != "linux" or shutil.which("Xvfb") is None:
        return None
    server = subprocess.Popen(["Xvfb", display, "-nolisten", "tcp"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    time.sleep(1.0)
    env = dict(os.environ, DISPLAY=display, QT_QPA_PLATFORM="xcb")
    code = "from PySide6.QtWidgets import QApplication; QApplication([])"
    probe = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=60)
    if server.poll() is not None or probe.returncode != 0:
        server.kill()
        return None
    return server


def test_a_real_display_lost_mid_run_ends_the_run_safely(tmp_path: Path) -> None:
    display = f":{90 + os.getpid() % 9}"
    server = _xvfb(display)
    if server is None:
        pytest.skip("needs Xvfb and Qt's xcb platform plugin (its X libraries)")
    out = tmp_path / "x.h5"
    env = dict(os.environ, DISPLAY=display, QT_QPA_PLATFORM="xcb", PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", RUN_AT_ONCE_SCRIPT, str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        wait_first_point(proc, out, 60)  # the display goes once a point is measured
        server.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=60)
    finally:
        server.kill()
        proc.kill()
    assert "The X11 connection broke" in stderr
    run = read_run(out)
    assert run.status == "aborted", stderr[-2000:]
    log = out.with_suffix(".log").read_text(encoding="utf-8")
    assert "run aborted: interrupted: the display went away" in log
    assert "safe state confirmed" in log
    assert not (tmp_path / "x.h5.lock").exists()
