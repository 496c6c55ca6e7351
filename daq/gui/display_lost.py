"""The display going away under the bench window: ``ssh -X`` dropped, the X server or the
Wayland compositor gone.

Qt then prints one warning ("The X11 connection broke (error 1). Did the X11 server die?", or
Wayland's "connection broke" line) and ends the process at once with ``exit(1)``, from the
window's thread: a run in progress was cut off where it stood, its generator output left on,
its file ``running`` with its lock, its log cut short (measured on Xvfb, killed mid-run).

:func:`watch_display` installs a Qt message handler that passes every message on as Qt would
and, on that warning, calls ``on_lost`` before Qt goes on to end the process. The bench window
aborts its run there and waits for the safe state and the file (:meth:`MainWindow.display_lost
<daq.gui.main_window.MainWindow.display_lost>`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

__all__ = ["LOST_MARK", "watch_display"]

#: what Qt's platform plugins say when their display connection breaks (xcb and Wayland)
LOST_MARK = "connection broke"


def watch_display(on_lost: Callable[[str], None]) -> Callable[[], None]:
    """Install the handler; returns the function that puts the previous one back."""
    from PySide6.QtCore import qInstallMessageHandler

    previous: Any = None

    def handler(mode: Any, context: Any, message: str) -> None:
        if previous is not None:
            previous(mode, context, message)
        else:  # Qt's own output: the message on the standard error
            try:
                sys.stderr.write(f"{message}\n")
                sys.stderr.flush()
            except (OSError, ValueError):
                pass
        if LOST_MARK in message:
            on_lost(message)

    previous = qInstallMessageHandler(handler)

    def restore() -> None:
        qInstallMessageHandler(previous)

    return restore
