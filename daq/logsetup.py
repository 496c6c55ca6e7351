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
    "HeldRunLog",
    "add_verbosity_arguments",
    "attach_run_log",
    "configure",
    "detach",
    "hold_run_log",
    "log_path_for",
    "verbosity",
]

#: the root of biafc-lab's loggers
LOGGER = "biafc"
_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


class _IsoFormatter(logging.Formatter):
    """Time stamps in ISO 8601 with the zone, to the millisecond
    ("2026-11-28T15:10:11.123+01:00"): the run file's own stamps are UTC, and a log line in
    local time without its zone could not be put beside them."""

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
        import datetime as dt

        when = dt.datetime.fromtimestamp(record.created).astimezone()
        return when.isoformat(timespec="milliseconds")


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


def _say_once(path: Path, exc: BaseException) -> None:
    """One line on stderr for a log file that cannot be written (not logging's traceback)."""
    why = getattr(exc, "strerror", None) or exc
    try:
        print(
            f"biafc: the log file {path} cannot be written ({why}); the run file's /log keeps "
            "the messages",
            file=sys.stderr,
            flush=True,
        )
    except (OSError, ValueError):
        pass


class _OnceFileHandler(logging.FileHandler):
    """A log file whose write errors (a folder turned read-only, a full disk) are said in one
    line, once, instead of a traceback per message; the messages stay in the run file's /log."""

    def __init__(self, path: Path) -> None:
        super().__init__(path, mode="a", encoding="utf-8", delay=False)
        self._said = False

    def handleError(self, record: logging.LogRecord) -> None:
        if not self._said:
            self._said = True
            _say_once(Path(self.baseFilename), sys.exc_info()[1] or OSError("write failed"))


class HeldRunLog(logging.Handler):
    """The log file beside a run file, opened only once the run file is this process's
    (:meth:`open_file`, called by the run engine right after it locks the file). Until then
    messages are held in memory; a run refused before it (another process writes the file,
    a dead instrument at connect) writes nothing: before, its "starting" and "refused" lines
    went into the other process's ``RUN.log``."""

    def __init__(self, path: Path) -> None:
        super().__init__(logging.INFO)
        self.path = path
        self.setFormatter(_IsoFormatter(_FORMAT))
        self._held: list[logging.LogRecord] = []
        self._file: logging.Handler | None = None

    def emit(self, record: logging.LogRecord) -> None:
        if self._file is None:
            self._held.append(record)
        else:
            self._file.emit(record)

    def open_file(self) -> None:
        """Open the log file (appending) and write the held messages to it; then every next
        one goes there at once. (Not ``release``: that is ``logging.Handler``'s lock.)"""
        with self.lock:  # type: ignore[union-attr]  # an RLock: emit may hold it
            if self._file is not None:
                return
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                f = _OnceFileHandler(self.path)
            except OSError as exc:  # a folder that turned read-only: the run file's /log has it
                _say_once(self.path, exc)
                self._held.clear()
                self._file = logging.NullHandler()
                return
            f.setLevel(logging.INFO)
            f.setFormatter(self.formatter)
            for record in self._held:
                f.emit(record)
            self._held.clear()
            self._file = f

    def close(self) -> None:
        if self._file is not None:
            try:
                self._file.close()
            except (OSError, ValueError):  # its last flush on a full disk: said already
                pass
        self._held.clear()
        super().close()


def attach_run_log(run_path: str | Path) -> logging.Handler:
    """Append every ``biafc`` message from INFO up to the log file beside ``run_path``;
    returns the handler (give it to :func:`detach` when the run ends)."""
    logger = logging.getLogger(LOGGER)
    logger.setLevel(logging.DEBUG)
    path = log_path_for(run_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, mode="a", encoding="utf-8", delay=False)
    handler.setLevel(logging.INFO)
    handler.setFormatter(_IsoFormatter(_FORMAT))
    logger.addHandler(handler)
    return handler


def hold_run_log(run_path: str | Path) -> HeldRunLog:
    """As :func:`attach_run_log`, but the file opens only at :meth:`HeldRunLog.open_file`."""
    logger = logging.getLogger(LOGGER)
    logger.setLevel(logging.DEBUG)
    handler = HeldRunLog(log_path_for(run_path))
    logger.addHandler(handler)
    return handler


def detach(handler: logging.Handler | None) -> None:
    """Remove and close a handler of :func:`attach_run_log` (None: nothing)."""
    if handler is None:
        return
    logging.getLogger(LOGGER).removeHandler(handler)
    handler.close()
