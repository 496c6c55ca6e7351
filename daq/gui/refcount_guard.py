"""Workaround: PySide6 6.12 on Python 3.11 drops references to ``None``/``True``/``False``.

Measured here (offscreen, PySide6-Essentials 6.12, CPython 3.11): every ``processEvents`` and
every Python override of a Qt virtual (pyqtgraph's ``paint`` and friends) returning
``None``/``bool`` loses one reference to that singleton: an idle plot window loses ~1000
references to ``None`` a second. When the count reaches zero CPython aborts with
"Fatal Python error: none_dealloc" (or ``bool_dealloc``), typically at exit or after minutes to
hours of a window left open at the bench. From CPython 3.12 these objects are immortal and the
bug is harmless, so the guard does nothing there.

:func:`install` starts a timer that, five times a second, tops the three singletons' reference
counts back up to the level seen at install time (extra references to them cost nothing:
they are never freed). The real fix is a PySide6 without the bug or Python >= 3.12.
"""

from __future__ import annotations

import atexit
import ctypes
import sys

from PySide6.QtCore import QCoreApplication, QTimer

__all__ = ["install", "top_up"]

_GUARDED = (None, True, False)
_MARGIN = 100_000
_baseline: dict[int, int] = {}
_timer: QTimer | None = None


def needed() -> bool:
    """True on interpreters whose ``None``/``True``/``False`` are not immortal (< 3.12)."""
    return sys.version_info < (3, 12)


def top_up() -> int:
    """Restore the guarded reference counts to at least their baseline; returns how many
    references were added."""
    added = 0
    incref = ctypes.pythonapi.Py_IncRef
    incref.argtypes = [ctypes.py_object]
    for obj in _GUARDED:
        want = _baseline.get(id(obj))
        if want is None:
            continue
        deficit = want - sys.getrefcount(obj)
        for _ in range(max(0, deficit)):
            incref(obj)
        added += max(0, deficit)
    return added


def install() -> bool:
    """Start the guard (idempotent; needs a Q(Core)Application). Returns True when active."""
    global _timer
    if not needed():
        return False
    if _timer is not None:
        return True
    app = QCoreApplication.instance()
    if app is None:
        return False
    incref = ctypes.pythonapi.Py_IncRef
    incref.argtypes = [ctypes.py_object]
    for obj in _GUARDED:
        for _ in range(_MARGIN):  # headroom for the drops between two ticks
            incref(obj)
        _baseline[id(obj)] = sys.getrefcount(obj)
    _timer = QTimer(app)
    _timer.setInterval(200)
    _timer.timeout.connect(top_up)
    _timer.start()
    atexit.register(top_up)
    return True
