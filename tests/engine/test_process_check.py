"""Whether the process named in a lock still runs, asked without signalling it
(:mod:`daq.store.process_check`): on Windows ``os.kill(pid, 0)`` terminates the process, so a
lock check with it would kill the live writer it protects."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from daq.store import process_check
from daq.store.lock import FileInUse, RunFileLock, in_use_by, lock_path
from daq.store.repair import _leftovers

#: a PID the fake Win32 query below reports as running, since the start time "42"
WRITER = 4242


@pytest.fixture
def windows(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """``sys.platform`` "win32", the Win32 query faked (the writer runs; this process too), and
    ``os.kill`` recorded and refused: there it would terminate the process it names."""
    killed: list[tuple[int, int]] = []

    def kill(pid: int, sig: int) -> None:
        killed.append((pid, sig))
        raise AssertionError(f"os.kill({pid}, {sig}) on Windows terminates process {pid}")

    def query(pid: int) -> tuple[bool, str | None]:
        return {WRITER: (True, "42"), os.getpid(): (True, "7")}.get(pid, (False, None))

    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setattr(os, "kill", kill)
    monkeypatch.setattr(process_check, "_win32_process", query)
    return killed


def _lock_of(run: Path, pid: int, started: str | None) -> None:
    content = {
        "host": socket.gethostname(),
        "pid": pid,
        "process_start": started,
        "since": "2026-11-27T23:00:00+0000",
        "command": "run_protocol ltr_highamp.yaml",
    }
    lock_path(run).write_text(json.dumps(content))


def test_on_windows_a_live_writer_is_refused_without_signalling_it(
    tmp_path: Path, windows: list[tuple[int, int]]
) -> None:
    run = tmp_path / "run.h5"
    _lock_of(run, WRITER, "42")
    with pytest.raises(FileInUse, match=f"being written by process {WRITER}"):
        RunFileLock(run).acquire()
    assert in_use_by(run) is not None
    part = tmp_path / f".run.h5.{WRITER}.part"  # the live writer's half-made file
    part.write_text("")
    assert _leftovers(run) == []
    assert windows == []


def test_on_windows_a_dead_or_reused_pid_is_stale_and_taken_over(
    tmp_path: Path, windows: list[tuple[int, int]]
) -> None:
    for pid, started in ((WRITER + 1, "42"), (WRITER, "41")):  # gone; its PID reused since
        run = tmp_path / f"run{pid}{started}.h5"
        _lock_of(run, pid, started)
        lock = RunFileLock(run).acquire()
        assert "taken over a stale lock" in lock.stale_note
        assert json.loads(lock_path(run).read_text())["process_start"] == "7"
        lock.release()
    assert windows == []


def test_on_windows_a_query_that_fails_counts_the_process_as_running(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A lock is never taken over on a guess: a failed query leaves the writer its lock."""

    def broken(pid: int) -> tuple[bool, str | None]:
        raise OSError("kernel32 call failed")

    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setattr(process_check, "_win32_process", broken)
    assert process_check.process_alive(WRITER, "42")
    assert process_check.process_start(WRITER) is None


def test_a_running_process_its_successor_and_its_end_on_this_host() -> None:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        started = process_check.process_start(child.pid)
        assert process_check.process_alive(child.pid, started)
        assert process_check.process_alive(child.pid, None)
        if started is not None:  # a start time to compare (Linux /proc, Windows)
            assert not process_check.process_alive(child.pid, started + "0")  # a reused PID
    finally:
        child.kill()
        child.wait()
    assert not process_check.process_alive(child.pid, started)
    assert child.poll() is not None


def test_no_pid_names_no_process() -> None:
    """On POSIX ``os.kill(0, 0)`` and ``os.kill(-1, 0)`` address process groups, and succeed."""
    assert not process_check.process_alive(0, None)
    assert not process_check.process_alive(-1, None)


def _kernel32() -> SimpleNamespace:
    """The four kernel32 calls as Microsoft documents them: ``OpenProcess`` returns 0 and sets
    the last error (87 no such process, 5 access denied); ``GetExitCodeProcess`` gives 259
    (STILL_ACTIVE) while the process runs; ``GetProcessTimes`` its creation FILETIME. Plain
    functions, which take the ``restype`` and ``argtypes`` the caller sets."""
    k = SimpleNamespace(error=0, open=set())
    procs = {10: (259, 0x01DB, 0x2345), 11: (0, 1, 2)}  # pid: exit code, creation high, low

    def open_process(access: int, inherit: bool, pid: int) -> int:
        assert access == 0x1000  # PROCESS_QUERY_LIMITED_INFORMATION: enough, for any user
        if pid == 12:
            k.error = 5
            return 0
        if pid not in procs:
            k.error = 87
            return 0
        k.open.add(1000 + pid)
        return 1000 + pid

    def exit_code(handle: int, code: Any) -> int:
        code._obj.value = procs[handle - 1000][0]
        return 1

    def times(handle: int, created: Any, *others: Any) -> int:
        created._obj.dwHighDateTime, created._obj.dwLowDateTime = procs[handle - 1000][1:]
        return 1

    def close(handle: int) -> int:
        k.open.remove(handle)
        return 1

    k.OpenProcess, k.GetExitCodeProcess, k.GetProcessTimes, k.CloseHandle = (
        open_process, exit_code, times, close,
    )  # fmt: skip
    return k


def test_the_win32_query_reads_running_ended_missing_and_foreign_processes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import ctypes

    k32 = _kernel32()
    monkeypatch.setattr(ctypes, "WinDLL", lambda name, use_last_error: k32, raising=False)
    monkeypatch.setattr(ctypes, "get_last_error", lambda: k32.error, raising=False)
    assert process_check._win32_process(10) == (True, str((0x01DB << 32) | 0x2345))
    assert process_check._win32_process(11) == (False, None)  # ended, a handle still open
    assert process_check._win32_process(13) == (False, None)  # no such process
    assert process_check._win32_process(12) == (True, None)  # another user's
    assert k32.open == set()  # every handle closed


@pytest.mark.skipif(sys.platform != "win32", reason="the Win32 process query runs on Windows only")
def test_the_win32_query_leaves_the_process_running() -> None:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        running, started = process_check._win32_process(child.pid)
        assert running and started is not None
        assert process_check.process_alive(child.pid, started)
        time.sleep(0.2)
        assert child.poll() is None  # still running after being asked
    finally:
        child.kill()
        child.wait()
    assert process_check._win32_process(child.pid)[0] is False


def test_run_protocol_forces_its_interrupt_without_pthread_kill(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The abort watchdog interrupts the main thread; Windows has no ``signal.pthread_kill``."""
    from daq.cli.run_protocol import _SignalGate

    monkeypatch.delattr(signal, "pthread_kill")
    got: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: got.append(signum))
    try:
        _SignalGate()._force()
    finally:
        signal.signal(signal.SIGINT, old)
    assert got == [signal.SIGINT]
