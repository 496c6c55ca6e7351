"""One logging setup for the command line and the bench window.

Every message goes through the standard :mod:`logging` tree under ``biafc`` (the run engine's
rows, which also go to the run file's ``/log``, under ``biafc.run``). :func:`configure` sets the
terminal's level from ``-v``/``-q`` (WARNING by default, INFO with ``-v``, DEBUG with ``-vv``,
ERROR with ``-q``); :func:`attach_run_log` adds a log file beside the run file (``RUN.log``,
appended on ``--resume``) that keeps everything from INFO up, whatever the terminal shows.

The run engine's warnings reach the terminal as events (the progress display prints them), so
the terminal handler leaves out ``biafc.run`` records at WARNING and above: each is printed once.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import TextIO

__all__ = [
    "LOGGER",
    "add_verbosity_arguments",
    "attach_run_log",
    "configure",
    "detach",
    "log_path_for",
    "verbosity",
]

#: the root of biafc-lab's loggers
LOGGER = "biafc"
_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


class _NotShownElsewhere(logging.Filter):
    """Drops the run engine's warnings and errors: the progress display prints those."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.name.startswith(f"{LOGGER}.run") and record.levelno >= logging.WARNING)


def add_verbosity_arguments(parser: argparse.ArgumentParser) -> None:
    """``-v/--verbose`` (repeatable) and ``-q/--quiet``."""
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more messages (-vv: debugging)"
    )
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="errors only, no progress display"
    )


def verbosity(args: argparse.Namespace) -> int:
    """-1 quiet, 0 default, 1 -v, 2 -vv."""
    return -1 if getattr(args, "quiet", False) else int(getattr(args, "verbose", 0) or 0)


def configure(level: int = 0, stream: TextIO | None = None) -> logging.Logger:
    """Set up the ``biafc`` logger for a terminal at verbosity ``level`` (see
    :func:`verbosity`); idempotent (replaces the handler it installed before)."""
    logger = logging.getLogger(LOGGER)
    logger.setLevel(logging.DEBUG)
    logger.propagate = False
    for h in list(logger.handlers):
        if getattr(h, "_biafc_terminal", False):
            logger.removeHandler(h)
    handler = logging.StreamHandler(stream if stream is not None else sys.stderr)
    handler._biafc_terminal = True  # type: ignore[attr-defined]
    handler.setLevel(
        {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(level, logging.DEBUG)
    )
    handler.setFormatter(logging.Formatter("%(name)s: %(levelname)s: %(message)s"))
    handler.addFilter(_NotShownElsewhere())
    logger.addHandler(handler)
    return logger


def log_path_for(run_path: str | Path) -> Path:
    """The log file beside a run file: ``RUN.h5`` -> ``RUN.log``."""
    return Path(run_path).with_suffix(".log")


def attach_run_log(run_path: str | Path) -> logging.Handler:
    """Append every ``biafc`` message from INFO up to the log file beside ``run_path``;
    returns the handler (give it to :func:`detach` when the run ends)."""
    logger = logging.getLogger(LOGGER)
    logger.setLevel(logging.DEBUG)
    path = log_path_for(run_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, mode="a", encoding="utf-8", delay=False)
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter(_FORMAT))
    logger.addHandler(handler)
    return handler


def detach(handler: logging.Handler | None) -> None:
    """Remove and close a handler of :func:`attach_run_log` (None: nothing)."""
    if handler is None:
        return
    logging.getLogger(LOGGER).removeHandler(handler)
    handler.close()
