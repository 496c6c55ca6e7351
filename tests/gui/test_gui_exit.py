"""The bench window's exit after a run file was left open on a full disk
(:mod:`protocols.left_open`): HDF5's clean-up crashed the process as the window closed
("Segmentation fault", status 139) after the run had been reported; now the window's process
ends with its own status, its logs flushed."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from daq.gui import app
from protocols import left_open

from .conftest import StubWindow, window_args

ROOT = Path(__file__).resolve().parents[2]


class _Ended(Exception):
    pass


@pytest.fixture
def window(qapp: Any, monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The window stubbed, Qt's event loop returning 3 at once, the exit without HDF5's
    clean-up recorded (run for real, it would run this process's exit handlers: h5py's among
    them)."""
    import daq.gui.main_window as main_window

    ended: list[int] = []

    def _exit(code: int) -> None:
        ended.append(code)
        raise _Ended

    monkeypatch.setattr(main_window, "MainWindow", StubWindow)
    monkeypatch.setattr(type(qapp), "exec", lambda self: 3)
    monkeypatch.setattr(left_open, "exit_leaving_them", _exit)
    monkeypatch.setattr("daq.logsetup.configure", lambda *a, **k: None)
    return ended


def test_the_window_ends_without_hdf5s_clean_up_when_a_file_was_left_open(window) -> None:
    left_open.leave_open("/data/run.h5")
    with pytest.raises(_Ended):
        app.run_window(window_args())
    assert window == [3]  # the window's own status


def test_the_window_returns_its_status_when_no_file_was_left_open(window) -> None:
    assert app.run_window(window_args()) == 3
    assert window == []


_SCRIPT = r"""
import sys
import h5py, numpy as np
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication
import daq.gui.main_window as main_window
from daq.gui import app
from protocols.left_open import leave_open

path = sys.argv[1]
f = h5py.File(path, "w", libver="latest")
d = f.create_dataset("v", shape=(100, 100000), dtype="f4", chunks=(1, 100000))
f.swmr_mode = True
try:
    for i in range(100):
        d[i] = np.ones(100000, "f4"); d.flush(); f.flush()
except RuntimeError:
    leave_open(path)  # as the run file's writer does after a failed write
else:
    sys.exit("the disk never filled")

class Window:
    def __init__(self, *a): pass
    def show(self): QTimer.singleShot(0, QApplication.instance().quit)
    def console_closed(self, what): pass
    def display_lost(self, message): pass
    def stop_signal(self, signum): pass

main_window.MainWindow = Window
ns = app.argparse.Namespace(bench=None, protocol=None, run=None, connect=False, verbose=0,
                            quiet=False)
print("window closed with", app.run_window(ns), flush=True)
"""


def test_the_window_after_a_real_full_disk_exits_0_not_139(tmp_path: Path) -> None:
    disk = tmp_path / "disk"
    disk.mkdir()
    try:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(disk)],
                                 capture_output=True, timeout=10).returncode == 0  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        mounted = False
    if sys.platform != "linux" or not mounted:
        pytest.skip("mounting a small tmpfs needs Linux and the right to mount (root)")
    try:
        env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(ROOT))
        done = subprocess.run([sys.executable, "-c", textwrap.dedent(_SCRIPT), str(disk / "r.h5")],
                              capture_output=True, text=True, timeout=120, env=env)  # fmt: skip
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True, timeout=30)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "window closed with" not in done.stdout  # it ended at the window's close
