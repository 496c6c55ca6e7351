"""Python's cyclic garbage collector runs on the GUI thread only, while a window is open.

The window starts worker threads (connect, snapshots, figure export, the run engine). Left on
automatic, the collector runs in whichever thread happens to allocate, and a garbage cycle that
holds a Qt object then destroys it off the GUI thread: ``QObject::~QObject`` takes a Qt lock
and waits for the GIL while the GUI thread, holding the GIL, waits for that lock. Seen here as
a figure export that never finished (a worker inside matplotlib, the GUI thread in
``QObject::~QObject``). pyqtgraph's :class:`~pyqtgraph.util.garbage_collector.GarbageCollector`
switches automatic collection off and collects on a GUI-thread timer instead; :func:`install`
starts it once per process, :func:`uninstall` gives automatic collection back.
"""

from __future__ import annotations

import gc
from typing import Any

__all__ = ["install", "installed", "uninstall"]

#: seconds between collections on the GUI thread
INTERVAL_S = 1.0

_collector: Any = None


def install() -> None:
    """Collect garbage on the GUI thread only (idempotent; needs a QApplication)."""
    global _collector
    if _collector is None:
        from pyqtgraph.util.garbage_collector import GarbageCollector

        _collector = GarbageCollector(interval=INTERVAL_S)


def installed() -> bool:
    return _collector is not None


def uninstall() -> None:
    """Stop the timer, collect once here (call on the GUI thread) and switch automatic
    collection back on."""
    global _collector
    if _collector is not None:
        _collector.timer.stop()
        _collector = None
    gc.collect()
    gc.enable()
