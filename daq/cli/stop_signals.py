"""The signals that stop a run, one rule for the console script's first moments
(:mod:`daq.cli.entry`) and for ``run_protocol``'s own handling (:mod:`daq.cli.run_protocol`):
SIGINT, SIGTERM and, where there is one and it is not ignored, SIGHUP (the terminal closed, or
the ssh link to it dropped). Under ``nohup`` SIGHUP is ignored: the run goes on, as ``nohup``
promises."""

from __future__ import annotations

import signal

__all__ = ["stop_signals"]


def stop_signals() -> tuple[int, ...]:
    """SIGINT, SIGTERM and SIGHUP unless this platform has none or it is ignored now."""
    hup: int | None = getattr(signal, "SIGHUP", None)
    if hup is None or signal.getsignal(hup) is signal.SIG_IGN:
        return (signal.SIGINT, signal.SIGTERM)
    return (signal.SIGINT, signal.SIGTERM, hup)
