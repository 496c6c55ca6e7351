"""The signals that stop a run, one rule for the console script's first moments
(:mod:`daq.cli.entry`) and for ``run_protocol``'s own handling (:mod:`daq.cli.run_protocol`):
SIGINT, SIGTERM, SIGBREAK on Windows (Ctrl-Break) and, where there is one and it is not ignored,
SIGHUP (the terminal closed, or the ssh link to it dropped). Under ``nohup`` SIGHUP is ignored:
the run goes on, as ``nohup`` promises. (A console window closed on Windows does not come as a
signal Python could handle in time: :mod:`daq.cli.console_close`.)"""

from __future__ import annotations

import signal

__all__ = ["stop_signals"]


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
