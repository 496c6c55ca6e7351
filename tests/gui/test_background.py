"""BackgroundCall: the worker thread never drops the last reference to a Qt object.

A QObject (the BackgroundCall, or a window its callback refers to) freed on a worker thread
runs ~QObject there, which takes Qt's mutex and then waits for the GIL while the GUI thread,
holding the GIL, deletes widgets and waits for that mutex: the full test suite hung that way
in test_window (gdb: Shiboken's GilState in ~QObject on a worker, QBasicMutex on the GUI
thread)."""

from __future__ import annotations

import gc
import threading
import time
import weakref
from typing import Any

import pytest

from daq.gui.background import BackgroundCall


def test_the_call_is_released_on_the_gui_thread(
    qtbot: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    work = BackgroundCall._work

    def slow_exit(self: BackgroundCall) -> None:
        work(self)
        time.sleep(0.3)  # the worker still holds the call while the GUI thread finishes it

    monkeypatch.setattr(BackgroundCall, "_work", slow_exit)
    freed_on: list[str] = []
    results: list[Any] = []
    call = BackgroundCall(lambda: 42, lambda r, e: results.append((r, e)))
    weakref.finalize(call, lambda: freed_on.append(threading.current_thread().name))
    worker = call.worker
    del call
    qtbot.waitUntil(lambda: bool(results), timeout=5000)
    assert results == [(42, None)]
    worker.join(5.0)
    qtbot.wait(50)
    gc.collect()
    qtbot.waitUntil(lambda: bool(freed_on), timeout=5000)
    assert freed_on == [threading.main_thread().name]
