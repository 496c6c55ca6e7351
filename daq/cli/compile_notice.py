"""The command line's notice while the DEM kernel compiles on first use (issue 19).

``install(stream)`` makes the model report a first-use compilation on ``stream``: one line when
it starts (what happens, that it happens once, where it is kept), the elapsed time on a terminal
(rewritten every second), and one line when it is done.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TextIO

__all__ = ["CompileNotice", "doing", "install", "ready_line", "start_line"]


class CompileNotice:
    """A :data:`sim_backend.dem.kernel_cache.CompileReporter` that writes to a stream.

    Without a stream it writes to ``sys.stderr`` as it is when the kernel compiles, not as it
    was when the notice was installed (a stream replaced since, e.g. closed by a test harness's
    capture, is not written to)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self._stream = stream

    @property
    def stream(self) -> TextIO:
        return self._stream if self._stream is not None else sys.stderr

    @property
    def tty(self) -> bool:
        try:
            return self.stream.isatty()
        except ValueError:  # a closed stream
            return False

    def __call__(self, phase: str, elapsed_s: float, folder: Path, cold: bool) -> None:
        if phase == "start":
            self.stream.write(start_line(folder, cold) + "\n")
        elif phase == "tick" and self.tty:
            self.stream.write(f"\r  {doing(cold)} the DEM kernel ... {elapsed_s:4.0f} s")
        elif phase == "done":
            lead = "\r" if self.tty else ""
            self.stream.write(f"{lead}  {ready_line(elapsed_s)}          \n")
        self.stream.flush()


def doing(cold: bool) -> str:
    """What happens to the kernel: "compiling" when nothing was on disk."""
    return "compiling" if cold else "loading or recompiling"


def start_line(folder: Path | str, cold: bool) -> str:
    """The notice's first line (the command line's and the bench window's)."""
    return (
        f"{doing(cold)} the DEM kernel for this machine: once per installation, usually "
        f"5-20 s; kept in {folder} (`biafc warmup` does it ahead of time)"
    )


def ready_line(elapsed_s: float) -> str:
    return f"DEM kernel ready after {elapsed_s:.1f} s"


def install(stream: TextIO | None = None) -> None:
    """Report first-use compilations of the DEM kernel on ``stream`` (default: the stderr of the
    moment each line is written)."""
    from sim_backend.dem.kernel_cache import set_compile_reporter

    set_compile_reporter(CompileNotice(stream))
