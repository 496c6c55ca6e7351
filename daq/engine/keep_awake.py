"""Keeping the computer awake while a run measures on a lab bench.

A bench PC set to sleep after some idle minutes (the default on many Windows machines, and on a
laptop) went to sleep in the middle of an overnight run: the run stood still until someone woke
the PC, with the generator armed, and the links to the instruments might not survive it. A run
on a lab bench now asks the system not to sleep until it ends (the screen may still turn off):

- Windows: ``SetThreadExecutionState(ES_CONTINUOUS | ES_SYSTEM_REQUIRED)`` on the run's thread,
  reset at its end (the request belongs to that thread);
- macOS: ``caffeinate -i -w PID`` for as long as the run;
- Linux: ``systemd-inhibit --what=sleep:idle --mode=block`` holding ``sleep infinity``, ended at
  the run's end.

Where the system offers none of these (no systemd, no session bus), the run goes on and its log
says that the power settings must keep the PC awake (:func:`cannot_line`). The simulated
bench holds nothing: a sleeping PC only pauses a simulation.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["ES_CONTINUOUS", "ES_SYSTEM_REQUIRED", "cannot_line", "keep_awake"]

#: SetThreadExecutionState's flags (winbase.h)
ES_CONTINUOUS = 0x80000000
ES_SYSTEM_REQUIRED = 0x00000001
#: how long a helper that cannot hold the system (no session bus) takes to say so (s)
_HELPER_START_S = 0.3


def _helper(which: Callable[[str], str | None], platform: str) -> list[str] | None:
    """The command that holds the system awake while it runs, or None."""
    if platform == "darwin" and (found := which("caffeinate")):
        return [found, "-i", "-w", str(os.getpid())]
    if platform.startswith("linux") and (found := which("systemd-inhibit")):
        return [found, "--what=sleep:idle", "--who=biafc-lab", "--why=a run is measuring",
                "--mode=block", "sleep", "infinity"]  # fmt: skip
    return None


@contextmanager
def keep_awake(
    kernel32: Any = None,
    which: Callable[[str], str | None] = shutil.which,
    platform: str | None = None,
) -> Iterator[tuple[str | None, str | None]]:
    """Hold the system awake for the ``with`` block; yields ``(what holds it, None)``, or
    ``(None, why nothing can)``. ``kernel32``, ``which`` and ``platform``: stand-ins for
    tests."""
    platform = sys.platform if platform is None else platform
    if platform == "win32" or kernel32 is not None:
        if kernel32 is None:
            import ctypes

            kernel32 = ctypes.WinDLL("kernel32")  # type: ignore[attr-defined]
        held = kernel32.SetThreadExecutionState(ES_CONTINUOUS | ES_SYSTEM_REQUIRED)
        try:  # 0: failed (or, the documentation allows it, a previous state of 0)
            if held:
                yield "SetThreadExecutionState(ES_CONTINUOUS | ES_SYSTEM_REQUIRED)", None
            else:
                yield None, "SetThreadExecutionState refused"
        finally:
            kernel32.SetThreadExecutionState(ES_CONTINUOUS)  # reset either way: harmless
        return
    cmd = _helper(which, platform)
    if cmd is None:
        yield None, "no caffeinate or systemd-inhibit here"
        return
    try:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)  # fmt: skip
    except OSError as exc:
        yield None, f"{os.path.basename(cmd[0])}: {exc.strerror or exc}"
        return
    try:
        proc.wait(_HELPER_START_S)
    except subprocess.TimeoutExpired:  # still holding: the system stays awake
        try:
            yield f"{os.path.basename(cmd[0])} {cmd[1]}", None
        finally:
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        return
    said = (proc.stderr.read() if proc.stderr else "").strip().splitlines()
    name = os.path.basename(cmd[0])
    yield None, f"{name}: {said[0] if said else f'exit {proc.returncode}'}"


def cannot_line(why: str) -> str:
    """The run log's line where nothing keeps the computer awake (``why``)."""
    return (
        f"cannot keep this computer from sleeping during the run ({why}): set its power "
        "settings to never sleep while a run measures"
    )
