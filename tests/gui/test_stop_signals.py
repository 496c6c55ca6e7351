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

import pytest

from protocols.runfile import PointState, read_run

from .conftest import RUN_AT_ONCE_SCRIPT

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _window(out: Path, script: str = RUN_AT_ONCE_SCRIPT) -> subprocess.Popen[str]:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-c", script, str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


def _first_point(proc: subprocess.Popen[str], out: Path) -> None:
    t_end = time.monotonic() + 90
    while time.monotonic() < t_end:
        assert proc.poll() is None, proc.communicate()
        try:
            if (read_run(out).scans["ltr"].done == PointState.DONE).any():
                return
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.1)
    raise AssertionError("no point measured in 90 s")


@pytest.mark.parametrize(("sig", "status"), [("SIGTERM", 1), ("SIGHUP", 1), ("SIGINT", 130)])
def test_a_stop_signal_mid_run_aborts_it_safely_and_exits_with_its_status(
    tmp_path: Path, sig: str, status: int
) -> None:
    out = tmp_path / "s.h5"
    proc = _window(out)
    try:
        _first_point(proc, out)
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
