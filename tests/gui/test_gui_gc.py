"""With the window open, garbage is collected on the GUI thread only, never in a worker thread
(a Qt object destroyed in a worker deadlocked the figure export)."""

from __future__ import annotations

import gc
import threading
import time
from typing import Any

from PySide6.QtCore import QObject

from daq.gui import gui_gc
from daq.gui.main_window import MainWindow


class _Cycle:
    def __init__(self) -> None:
        self.me = self
        self.qt = QObject()  # a Qt object only a garbage cycle holds


def _collections_by_thread(qtbot: Any) -> set[str]:
    """Names of the threads that ran a collection while a worker allocated cycles."""
    seen: set[str] = set()

    def record(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            seen.add(threading.current_thread().name)

    def allocate() -> None:
        for _ in range(20_000):
            a: list[Any] = []
            a.append(a)  # cyclic garbage: pushes the collector's counters

    for _ in range(50):
        _Cycle()  # garbage holding Qt objects, made on the GUI thread
    gc.callbacks.append(record)
    try:
        worker = threading.Thread(target=allocate, name="worker")
        worker.start()
        while worker.is_alive():
            qtbot.wait(20)
        deadline = time.monotonic() + 3 * gui_gc.INTERVAL_S
        while time.monotonic() < deadline and not seen:
            qtbot.wait(50)
    finally:
        gc.callbacks.remove(record)
    return seen


def test_with_the_window_open_only_the_gui_thread_collects(qtbot: Any) -> None:
    window = MainWindow()
    qtbot.addWidget(window)
    assert gui_gc.installed() and not gc.isenabled()
    seen = _collections_by_thread(qtbot)
    assert seen == {threading.main_thread().name}, seen


def test_uninstall_gives_automatic_collection_back(qtbot: Any) -> None:
    window = MainWindow()
    qtbot.addWidget(window)
    gui_gc.uninstall()
    assert gc.isenabled() and not gui_gc.installed()
