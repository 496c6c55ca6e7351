"""Closing the console window on Windows (or logging off, or shutting down) during a run.

Windows sends a console program ``CTRL_CLOSE_EVENT`` when its window is closed, and ends the
process as soon as the handler returns, or after about 5 s. The C runtime's own handler (the
one behind Python's signals) returns at once, so the run was cut off where it stood: the
generator's output on, the file ``running``, the log cut short, as SIGHUP did on Linux.

:func:`hold_console_close` registers a handler (``SetConsoleCtrlHandler``, called before the
runtime's) that runs ``on_close`` in the thread Windows calls it on and returns only when
``on_close`` does: ``run_protocol`` aborts the run there and waits, within Windows' bound, until
the safe state is set and the outcome written. Ctrl-C and Ctrl-Break are left to Python's
signal handling (:mod:`daq.cli.stop_signals`).
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["CLOSE_BOUND_S", "CLOSE_EVENTS", "ConsoleCloseHold", "hold_console_close"]

#: how long a handler may hold the process (s): Windows ends it about 5 s after a close event
CLOSE_BOUND_S = 4.5

#: ``CTRL_CLOSE_EVENT``, ``CTRL_LOGOFF_EVENT``, ``CTRL_SHUTDOWN_EVENT`` (wincon.h): name of each
CLOSE_EVENTS = {2: "console window closed", 5: "user logged off", 6: "system shutting down"}


class ConsoleCloseHold:
    """A registered handler; :meth:`remove` unregisters it."""

    def __init__(self, kernel32: Any, callback: Any) -> None:
        self._kernel32 = kernel32
        self._callback = callback  # referenced while registered: Windows calls into it

    def remove(self) -> None:
        if self._callback is not None:
            self._kernel32.SetConsoleCtrlHandler(self._callback, False)
            self._callback = None


def hold_console_close(
    on_close: Callable[[str], None], kernel32: Any = None
) -> ConsoleCloseHold | None:
    """Windows: call ``on_close(what)`` (``what``: :data:`CLOSE_EVENTS`' words) when the console
    window closes, the user logs off or the system shuts down, and let Windows end the process
    only once it returns. ``None`` elsewhere, or where the console API refuses the handler.
    ``kernel32``: the DLL (tests pass a stand-in)."""
    if kernel32 is None:
        if sys.platform != "win32":
            return None
        kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)  # type: ignore[attr-defined]
    functype = getattr(ctypes, "WINFUNCTYPE", ctypes.CFUNCTYPE)  # stdcall where there is one

    def handler(event: int) -> int:
        what = CLOSE_EVENTS.get(int(event))
        if what is None:
            return 0  # Ctrl-C, Ctrl-Break: the next handler (Python's signals)
        try:
            on_close(what)
        except BaseException:  # nothing may escape into the thread Windows calls it on
            pass
        return 1

    callback = functype(ctypes.c_int, ctypes.c_uint)(handler)
    if not kernel32.SetConsoleCtrlHandler(callback, True):
        return None
    return ConsoleCloseHold(kernel32, callback)
