"""The signals that stop a run, one rule for the console script's first moments
(:mod:`daq.cli.entry`) and for ``run_protocol``'s own handling (:mod:`daq.cli.run_protocol`):
SIGINT, SIGTERM, SIGBREAK on Windows (Ctrl-Break) and, where there is one and it is not ignored,
SIGHUP (the terminal closed, or the ssh link to it dropped). Under ``nohup`` SIGHUP is ignored:
the run goes on, as ``nohup`` promises. (A console window closed on Windows does not come as a
signal Python could handle in time: :mod:`daq.cli.console_close`.)"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

__all__ = [
    "StopSignal",
    "leave_the_terminal",
    "raise_if_stopped",
    "stop_signals",
    "stop_signals_interrupt",
]


class StopSignal(KeyboardInterrupt):
    """A stop signal other than SIGINT, raised where Ctrl-C's KeyboardInterrupt would be, so
    that a command ends through its Ctrl-C path (files closed, the same advice printed).
    ``signum``: the signal; the exit status is 128 + it."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def stop_signals() -> tuple[int, ...]:
    """SIGINT, SIGTERM, SIGBREAK where there is one (Windows), and SIGHUP unless this platform
    has none or it is ignored now."""
    out: list[int] = [signal.SIGINT, signal.SIGTERM]
    brk: int | None = getattr(signal, "SIGBREAK", None)  # Ctrl-Break ended the run where it was
    if brk is not None:
        out.append(brk)
    hup: int | None = getattr(signal, "SIGHUP", None)
    if hup is not None and signal.getsignal(hup) is not signal.SIG_IGN:
        out.append(hup)
    return tuple(out)


#: ``[signal, monotonic time]`` of the stop signal raised within
#: :func:`stop_signals_interrupt`; empty when none
_raised: list[Any] = []
#: a stop signal this long after the one raised raises again (s): the first was swallowed where
#: it landed, or the clean-up hangs; sooner, it is the same stop (ignored)
REPEAT_AFTER_S = 5.0


def _raise_stop(signum: int, frame: FrameType | None) -> None:
    if signum == getattr(signal, "SIGHUP", None):
        leave_the_terminal()  # a line printed on the way out would fail: the terminal is gone
    now = time.monotonic()
    if _raised and now - _raised[1] < REPEAT_AFTER_S:
        # a second one (systemd sends SIGTERM then SIGHUP): the first is on its way, and a
        # raise now could land in the clean-up (a thread's join, a file's close)
        return
    # the first one, or one long after it: that one was lost (swallowed where it landed)
    _raised[:] = [_raised[0] if _raised else signum, now]
    raise StopSignal(signum)


#: a SIGINT came within :func:`stop_signals_interrupt` (each one raises KeyboardInterrupt, as
#: Python's own handler does; this keeps it for :func:`raise_if_stopped`)
_interrupted: list[bool] = []


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    _interrupted[:] = [True]
    raise KeyboardInterrupt


def raise_if_stopped() -> None:
    """At a safe point of a long command (a study's task boundary): raise the
    :class:`StopSignal` of a signal that came before, or KeyboardInterrupt for a Ctrl-C, in
    case Python swallowed it where it landed (an exception in a weakref callback is printed and
    dropped: the study ran on with its output open, and exited 0)."""
    if _raised:
        raise StopSignal(_raised[0])
    if _interrupted:
        raise KeyboardInterrupt


@contextmanager
def stop_signals_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM, SIGHUP (unless ignored) and SIGBREAK raise :class:`StopSignal`
    as SIGINT raises KeyboardInterrupt: a ``kill``, a closed terminal or a batch system's time
    limit ends a ``biafc`` command the way Ctrl-C does, not by the default action, which left
    a study's output open for writing (readable only after ``biafc repair``). Only the first
    such signal raises; later ones are ignored unless :data:`REPEAT_AFTER_S` has passed. SIGINT
    raises KeyboardInterrupt each time, as Python's own handler does, and is remembered for
    :func:`raise_if_stopped`. The previous handlers come back at the end.
    Off the main thread (where Python cannot install handlers) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _raised.clear()
    _interrupted.clear()
    old = {s: signal.signal(s, _raise_stop) for s in stop_signals() if s != signal.SIGINT}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when ignored
        old[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupt)
    old_hook = sys.unraisablehook

    def quiet_stop(unraisable: Any) -> None:
        # a stop signal that landed where Python drops exceptions (a weakref callback) is
        # raised again at the next safe point: its "Exception ignored in" traceback is noise
        if isinstance(unraisable.exc_value, KeyboardInterrupt) and (_raised or _interrupted):
            return
        old_hook(unraisable)

    sys.unraisablehook = quiet_stop
    try:
        yield
    finally:
        sys.unraisablehook = old_hook
        for s, h in old.items():
            signal.signal(s, h)
        _raised.clear()
        _interrupted.clear()


def leave_the_terminal() -> None:
    """After SIGHUP: the terminal is gone, and a write to it could fail or block the abort. The
    standard output and error go to the null device from here on; the run's log file
    (``RUN.log``) and the run file keep the outcome."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        pass
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
    finally:
        os.close(null)
