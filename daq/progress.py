"""Progress of long jobs, one way for every command: a live ``rich`` bar with rate and ETA on a
terminal, plain lines when piped (a log, CI), nothing when quiet.

Used by ``run_protocol`` (points), ``biafc simulate`` (stages), ``biafc accuracy`` (runs of the
ladders) and ``python -m benchmarks`` (benchmarks). The caller says how far it is
(:meth:`ProgressDisplay.update`) and, when it knows better than the rate so far (the run
engine's ETA from the bench and the measured point times), the time left; otherwise the ETA is
the remaining count over the measured rate (:class:`ProgressDisplay`: from the first finished
item, or wave of items, on).

Plain lines read ``point 3/31: ltr 4 um cyl 3, 2.5 points/s, ETA 00:11`` (at most one a second,
and always the last one).
"""

from __future__ import annotations

import math
import sys
import time
from types import TracebackType
from typing import Any, TextIO

__all__ = ["ProgressDisplay", "format_duration", "format_minutes", "format_rate"]


def format_minutes(seconds: float) -> str:
    """``"2 min 30 s"`` or ``"45 s"``: an upper bound said in words (rounded up to the whole
    second, past 10 ms), as the homing's; ``"an unknown time"`` when not finite."""
    if not math.isfinite(seconds):
        return "an unknown time"
    minutes, s = divmod(math.ceil(round(max(0.0, seconds), 2)), 60)
    return f"{minutes} min {s} s" if minutes else f"{s} s"


def format_duration(seconds: float) -> str:
    """``mm:ss`` (or ``h:mm:ss``); ``--:--`` when unknown."""
    if not math.isfinite(seconds):
        return "--:--"
    h, rem = divmod(round(max(0.0, seconds)), 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


def format_rate(count: int, seconds: float, unit: str) -> str:
    """``2.5 points/s``, or ``12 s/point`` when slower than one a second; ``-`` before any."""
    if count <= 0 or seconds <= 0:
        return f"- {unit}s/s"
    rate = count / seconds
    if rate >= 1.0:
        return f"{rate:.3g} {unit}s/s"
    return f"{1.0 / rate:.3g} s/{unit}"


class ProgressDisplay:
    """A progress display on ``stream`` (default stderr) for ``total`` items of ``unit``.

    ``update(done, detail=..., eta_s=...)`` moves it; ``note(text)`` prints a line above a live
    bar (warnings); ``close()`` (or leaving the ``with`` block) ends the bar. ``live``: force
    (True) or forbid (False) the live bar; default: a live bar when ``stream`` is a terminal.

    The rate is counted from the ``steady_after``-th finished item on (default the first),
    once more are done: what comes before it (homing, compiling the model, starting a study's
    workers) is paid once, and read "15.4 s/point" on the simulated bench's first run, where
    the points took 0.02 s. Work done in parallel waves gives ``steady_after`` as one wave's
    items: its first wave ends within milliseconds, which is no rate.
    """

    def __init__(
        self,
        total: int,
        *,
        unit: str = "point",
        label: str = "",
        stream: TextIO | None = None,
        quiet: bool = False,
        live: bool | None = None,
        plain_every_s: float = 1.0,
        start_done: int = 0,
        steady_after: int = 1,
    ) -> None:
        self.total = max(int(total), 0)
        self.steady_after = max(int(steady_after), 1)
        self.unit = unit
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        isatty = getattr(self.stream, "isatty", None)
        self.live = (bool(isatty()) if callable(isatty) else False) if live is None else live
        self.plain_every_s = plain_every_s
        self.done = start_done
        self._start_done = start_done
        self._t0 = time.monotonic()
        #: (time, done) at the update that finished the ``steady_after``-th item: the steady
        #: rate's start
        self._first: tuple[float, int] | None = None
        self._last_plain = -math.inf
        self._progress: Any = None
        self._task: Any = None
        self._closed = False
        if not self.quiet and self.live:
            self._start_live()

    # -- the live bar (rich) ---------------------------------------------------------------
    def _start_live(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        console = Console(file=self.stream, force_terminal=True)
        self.console = console
        self._progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[rate]}"),
            TextColumn("ETA [cyan]{task.fields[eta]}"),
            TextColumn("{task.fields[detail]}"),
            console=console,
            refresh_per_second=8,
        )
        self._task = self._progress.add_task(
            self.label or f"{self.unit}s",
            total=self.total or None,
            completed=self.done,
            rate=format_rate(0, 0.0, self.unit),
            eta="--:--",
            detail="",
        )
        self._progress.start()

    # -- the caller's side -----------------------------------------------------------------
    def _counted(self) -> tuple[int, float]:
        """(items, seconds) the rate is measured over: from the ``steady_after``-th finished
        item on once there are more, else from the start."""
        now = time.monotonic()
        if self._first is not None and self.done > self._first[1]:
            return self.done - self._first[1], now - self._first[0]
        return self.done - self._start_done, now - self._t0

    def rate_text(self) -> str:
        return format_rate(*self._counted(), self.unit)

    def eta_from_rate(self) -> float:
        """Seconds left at the measured rate (:meth:`_counted`; inf before any item)."""
        n, dt = self._counted()
        if n <= 0 or dt <= 0:
            return math.inf
        return (self.total - self.done) * dt / n

    def update(self, done: int, *, detail: str = "", eta_s: float | None = None) -> None:
        """``done`` of ``total`` finished; ``detail`` says which; ``eta_s``: the time left when
        the caller knows it better than the rate (else it follows from the rate)."""
        self.done = int(done)
        if self._first is None and self.done - self._start_done >= self.steady_after:
            self._first = (time.monotonic(), self.done)
        if self.quiet or self._closed:
            return
        eta = format_duration(self.eta_from_rate() if eta_s is None else eta_s)
        if self._progress is not None:
            self._progress.update(
                self._task, completed=self.done, rate=self.rate_text(), eta=eta, detail=detail
            )
            return
        now = time.monotonic()
        last = self.total and self.done >= self.total
        if last or now - self._last_plain >= self.plain_every_s:
            self._last_plain = now
            where = f": {detail}" if detail else ""
            print(
                f"{self.unit} {self.done}/{self.total}{where}, {self.rate_text()}, ETA {eta}",
                file=self.stream,
                flush=True,
            )

    def note(self, text: str) -> None:
        """A line of its own (above a live bar)."""
        if self.quiet:
            return
        if self._progress is not None:
            self._progress.console.print(text, markup=False, highlight=False)
        else:
            print(text, file=self.stream, flush=True)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._progress is not None:
            self._progress.stop()

    def __enter__(self) -> ProgressDisplay:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
