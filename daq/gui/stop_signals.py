"""Stop signals reaching the bench window: SIGTERM (``kill``, a log-out), SIGHUP (the terminal or
the ``ssh`` session it was started from closed) and Ctrl-C in that terminal.

Before, SIGTERM and SIGHUP ended the process at once by their default action: a run was cut off
where it stood, the generator's output left on, the file ``running`` with its lock, the log cut
short. Ctrl-C did nothing until the next Python slot ran, and then only printed a
``KeyboardInterrupt`` traceback. Now each asks the window to close as its own Close does,
without the question: a run is aborted and its safe state and file are waited for
(:meth:`MainWindow.stop_signal <daq.gui.main_window.MainWindow.stop_signal>`), and the process
ends with the run's exit status, as ``run_protocol``'s would.

Qt's event loop runs no Python while it waits, so a Python signal handler could wait for ever:
:func:`close_on_stop_signals` points Python's wakeup file descriptor at a socket that a
``QSocketNotifier`` watches, so the loop wakes when a signal arrives and the handler runs. The
signals are those of :func:`daq.cli.stop_signals.stop_signals` (SIGHUP not under ``nohup``).
"""

from __future__ import annotations

import signal
import socket
from collections.abc import Callable
from types import FrameType
from typing import Any

from daq.cli.stop_signals import leave_the_terminal, stop_signals

__all__ = ["close_on_stop_signals"]


def close_on_stop_signals(on_signal: Callable[[int], None]) -> Callable[[], None]:
    """Call ``on_signal(signum)`` on the Qt thread, from the event loop, for each stop signal;
    after SIGHUP the standard output and error go to the null device first. Returns the
    function that puts the previous handlers back."""
    from PySide6.QtCore import QSocketNotifier, QTimer

    reader, writer = socket.socketpair()
    reader.setblocking(False)
    writer.setblocking(False)
    old_fd = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)

    def handler(signum: int, frame: FrameType | None) -> None:
        if signum == getattr(signal, "SIGHUP", None):
            leave_the_terminal()  # a write to the closed terminal could fail or block
        QTimer.singleShot(0, lambda: on_signal(signum))

    def drain() -> None:  # the handler has run by now (Python runs it before this slot)
        try:
            while reader.recv(64):
                pass
        except OSError:
            pass

    notifier: Any = QSocketNotifier(reader.fileno(), QSocketNotifier.Type.Read)
    notifier.activated.connect(drain)
    old = {s: signal.signal(s, handler) for s in stop_signals()}

    def restore() -> None:
        for s, h in old.items():
            signal.signal(s, h)
        signal.set_wakeup_fd(old_fd)
        notifier.setEnabled(False)
        reader.close()
        writer.close()

    return restore
