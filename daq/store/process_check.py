"""Whether a process of this host still runs, and when it started, without signalling it.

The run-file lock (:mod:`daq.store.lock`) and ``biafc repair`` ask this about the process named
in a lock or a half-made file. On POSIX ``os.kill(pid, 0)`` tests a process and sends nothing.
On Windows it does not test anything: every signal but ``CTRL_C_EVENT`` and ``CTRL_BREAK_EVENT``
terminates the process (``TerminateProcess``), so a lock check with it would kill the very writer
it protects, mid-scan and without its safe state. There the process is opened for a query
instead (``OpenProcess``, ``GetExitCodeProcess``, ``GetProcessTimes``).

A process's start time tells a reused PID from the process that wrote a lock: clock ticks since
boot on Linux (``/proc/PID/stat``), the creation time in 100 ns units on Windows, ``None``
elsewhere (then a live PID counts as the writer).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["process_alive", "process_start"]

#: Win32 constants (``processthreadsapi.h``, ``winerror.h``, ``minwinbase.h``)
_QUERY_LIMITED_INFORMATION = 0x1000
_ERROR_ACCESS_DENIED = 5
_STILL_ACTIVE = 259


def process_start(pid: int) -> str | None:
    """The start time of process ``pid`` as a string to compare, or ``None`` where it cannot be
    read (no such process, another user's on Windows, a system without ``/proc``)."""
    if sys.platform == "win32":
        try:
            return _win32_process(pid)[1]
        except (OSError, AttributeError, ValueError):  # the query failed: no time to compare
            return None
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def process_alive(pid: int, started: str | None) -> bool:
    """Whether process ``pid`` of this host runs and, when ``started`` is given and its start
    time can be read, is the process that started then (not a later one with the same PID).
    Never signals the process. A PID of 0 or below names no process (on POSIX it would name a
    process group)."""
    if pid <= 0:
        return False
    if sys.platform == "win32":
        try:
            running, now = _win32_process(pid)
        except (OSError, AttributeError, ValueError):  # the query failed: never a guessed takeover
            return True
    else:
        try:
            os.kill(pid, 0)  # POSIX: signal 0 checks that the process exists, sends nothing
        except ProcessLookupError:
            return False
        except PermissionError:
            return True  # exists, owned by someone else
        running, now = True, process_start(pid)
    return running and (started is None or now is None or now == started)


def _win32_process(pid: int) -> tuple[bool, str | None]:
    """``(running, start time)`` of process ``pid`` from the Win32 API: ``(True, None)`` for
    a process this user may not open (it exists), ``(False, None)`` for no such process."""
    import ctypes
    from ctypes import wintypes

    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)  # type: ignore[attr-defined]
    kernel32.OpenProcess.restype = wintypes.HANDLE
    kernel32.OpenProcess.argtypes = (wintypes.DWORD, wintypes.BOOL, wintypes.DWORD)
    kernel32.GetExitCodeProcess.argtypes = (wintypes.HANDLE, ctypes.POINTER(wintypes.DWORD))
    kernel32.GetProcessTimes.argtypes = (wintypes.HANDLE, *[ctypes.POINTER(wintypes.FILETIME)] * 4)
    kernel32.CloseHandle.argtypes = (wintypes.HANDLE,)
    handle = kernel32.OpenProcess(_QUERY_LIMITED_INFORMATION, False, pid)
    if not handle:
        return ctypes.get_last_error() == _ERROR_ACCESS_DENIED, None  # type: ignore[attr-defined]
    try:
        code = wintypes.DWORD()
        if kernel32.GetExitCodeProcess(handle, ctypes.byref(code)) and code.value != _STILL_ACTIVE:
            return False, None
        created, ended, kernel, user = (wintypes.FILETIME() for _ in range(4))
        refs = (ctypes.byref(t) for t in (created, ended, kernel, user))
        if not kernel32.GetProcessTimes(handle, *refs):
            return True, None
        return True, str((created.dwHighDateTime << 32) | created.dwLowDateTime)
    finally:
        kernel32.CloseHandle(handle)
