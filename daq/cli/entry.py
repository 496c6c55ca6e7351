"""Console-script entry points that are quiet about Ctrl-C from their first instruction.

``run_protocol`` (the console script) imports this module first: a SIGINT/SIGTERM (or SIGHUP,
unless ignored as under ``nohup``) while the interpreter is still importing the program (before
``run_protocol.main`` installs its own handling) ends it with one line and exit status 130 (128
+ the signal's number for the others), not a ``KeyboardInterrupt`` traceback. Nothing has been
opened or written at that point. Only console scripts import this module: importing it
installs the handler (its one job).
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

from daq.cli.stop_signals import stop_signals

__all__ = ["run_protocol"]

_PROG = "run_protocol"


def _before_start(signum: int, frame: FrameType | None) -> None:
    name = signal.Signals(signum).name
    try:
        os.write(
            2,
            f"{_PROG}: interrupted by {name} before the run started: nothing was switched on, "
            "no file written\n".encode(),
        )
    except OSError:  # SIGHUP: the terminal is gone
        pass
    os._exit(130 if signum == signal.SIGINT else 128 + signum)


_SIGNALS = stop_signals()  # SIGHUP too, unless ignored (nohup)
for _sig in _SIGNALS:
    signal.signal(_sig, _before_start)


def run_protocol() -> int:
    """``run_protocol``: :func:`daq.cli.run_protocol.main` (which handles Ctrl-C itself from
    its first line); once it has returned, a late Ctrl-C no longer changes the exit status,
    and the interpreter's shutdown is made quick (:func:`daq.cli.shutdown.settle`)."""
    from daq.cli.run_protocol import main
    from daq.cli.shutdown import settle

    try:
        return main()
    finally:
        for sig in _SIGNALS:  # the outcome is decided: keep its status
            signal.signal(sig, signal.SIG_IGN)
        settle()


if __name__ == "__main__":
    sys.exit(run_protocol())
