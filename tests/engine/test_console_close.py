"""Closing the console window on Windows during a run (:mod:`daq.cli.console_close`): Windows
ends the process as soon as its console handler returns, and the C runtime's handler returned at
once, so the run was cut off where it stood (outputs on, file ``running``). Now run_protocol's
handler aborts the run and returns once the outcome is written. Windows' kernel32 is replaced
by a stand-in that keeps the handler, and the test calls it on a thread of its own, as Windows
does, then ends the process as Windows would."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from daq.cli.console_close import CLOSE_BOUND_S, CLOSE_EVENTS, hold_console_close
from daq.cli.stop_signals import stop_signals
from protocols.runfile import PointState, read_run

TESTS = Path(__file__).resolve().parents[1]


class Kernel32:
    """``SetConsoleCtrlHandler`` as Microsoft documents it: add or remove a handler, nonzero
    on success."""

    def __init__(self, ok: bool = True) -> None:
        self.handlers: list[Any] = []
        self.ok = ok

    def SetConsoleCtrlHandler(self, handler: Any, add: bool) -> int:
        if not self.ok:
            return 0
        (self.handlers.append if add else self.handlers.remove)(handler)
        return 1


def test_the_handler_takes_the_close_events_and_leaves_ctrl_c_to_python() -> None:
    seen: list[str] = []
    k = Kernel32()
    hold = hold_console_close(seen.append, kernel32=k)
    assert hold is not None and len(k.handlers) == 1
    handler = k.handlers[0]
    assert handler(0) == 0 and handler(1) == 0  # CTRL_C_EVENT, CTRL_BREAK_EVENT: not ours
    assert handler(2) == 1 and handler(5) == 1 and handler(6) == 1
    assert seen == [CLOSE_EVENTS[2], CLOSE_EVENTS[5], CLOSE_EVENTS[6]]
    hold.remove()
    hold.remove()
    assert k.handlers == []


def test_nothing_escapes_the_handler_and_a_refused_handler_is_none() -> None:
    def fails(what: str) -> None:
        raise RuntimeError(what)

    k = Kernel32()
    hold_console_close(fails, kernel32=k)
    assert k.handlers[0](2) == 1
    assert hold_console_close(fails, kernel32=Kernel32(ok=False)) is None
    if sys.platform != "win32":
        assert hold_console_close(fails) is None  # no console API here


def test_ctrl_break_stops_a_run_on_windows(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("signal.SIGBREAK", 21, raising=False)
    assert 21 in stop_signals()


_SCRIPT = r"""
import os, sys, threading, time
import daq.cli.console_close as cc
from engine import fake_cli

class Kernel32:
    handlers = []
    def SetConsoleCtrlHandler(self, handler, add):
        (self.handlers.append if add else self.handlers.remove)(handler)
        return 1

k = Kernel32()
real = cc.hold_console_close
cc.hold_console_close = lambda on_close, kernel32=None: real(on_close, kernel32=k)

def windows():  # the window is closed once points are being measured
    while not (fake_cli.rp._GATE is not None and fake_cli.rp._GATE.ran):
        time.sleep(0.02)
    time.sleep(0.4)
    t0 = time.monotonic()
    returned = k.handlers[-1](2)  # CTRL_CLOSE_EVENT, on a thread of Windows' own
    with open(os.environ["CLOSE_REPORT"], "w") as f:
        f.write(f"{returned} {time.monotonic() - t0:.3f} OUTPUTS {fake_cli.WORLD.outputs}\n")
    os._exit(99)  # Windows ends the process once its handler returns

threading.Thread(target=windows, daemon=True).start()
fake_cli.rp.main(sys.argv[1:])
time.sleep(60)
"""


def test_a_closed_console_window_aborts_safely_before_windows_ends_the_process(
    proto_file: Path, tmp_path: Path
) -> None:
    out, report = tmp_path / "close.h5", tmp_path / "report.txt"
    env = dict(os.environ, FAKE_READ_S="0.05", PYTHONPATH=str(TESTS), CLOSE_REPORT=str(report))
    cmd = [sys.executable, "-c", _SCRIPT, str(proto_file), "--out", str(out)]
    done = subprocess.run(cmd, cwd=TESTS, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 99, done.stderr[-2000:]  # ended by "Windows", after the handler
    returned, seconds, outputs = report.read_text().split(" ", 2)
    assert returned == "1" and float(seconds) < CLOSE_BOUND_S
    assert outputs == "OUTPUTS {1: False, 2: False}\n"  # the safe state, before the end
    run = read_run(out)
    measured = sum(int((s.done == PointState.DONE).sum()) for s in run.scans.values())
    assert run.status == "aborted" and 0 < measured < sum(s.done.size for s in run.scans.values())
    assert any("interrupted: console window closed" in m for _, _, m in run.log)
    log = out.with_suffix(".log").read_text(encoding="utf-8")
    assert "run aborted: interrupted: console window closed" in log
    assert "safe state confirmed" in log
    assert not (tmp_path / "close.h5.lock").exists()
