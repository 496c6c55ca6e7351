"""The run file's lock under races: a writer slow (or killed) while taking it, and several
processes taking over one stale lock at once (:mod:`daq.store.lock`)."""

from __future__ import annotations

import errno
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from daq.store.lock import FileInUse, RunFileLock, lock_path, read_lock

#: a child that takes the lock of RUN (argv[1]) and says what happened on stdout; argv[2]
#: names the slowdown: "info" (slow to gather its lock's content), "stale" (slow to judge a
#: lock stale), argv[3] a file it waits for before it starts
_CHILD = r"""
import os, sys, time
from pathlib import Path
import daq.store.lock as L

run, slow, go = sys.argv[1], sys.argv[2], Path(sys.argv[3])
if slow == "info":
    real_info = L.RunFileLock._info
    def info(self):
        Path(run + ".started").write_text("")
        time.sleep(3.0)  # preempted, or merely slow, while taking the lock
        return real_info(self)
    L.RunFileLock._info = info
elif slow == "stale":
    real_stale = L.RunFileLock._stale
    def stale(other):
        verdict = real_stale(other)
        time.sleep(0.3)  # every process has judged the lock stale before any acts on it
        return verdict
    L.RunFileLock._stale = staticmethod(stale)
while not go.exists():
    time.sleep(0.005)
lock = L.RunFileLock(run)
try:
    lock.acquire()
except L.FileInUse as exc:
    print("refused:", exc, flush=True)
    sys.exit(0)
print("won", os.getpid(), flush=True)
time.sleep(2.0)
lock.release()
"""


def _child(run: Path, slow: str, go: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(run), slow, str(go)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_a_slow_writer_never_leaves_an_empty_lock_and_one_of_two_wins(tmp_path: Path) -> None:
    """A writer stalled while taking the lock (here 3 s while gathering what it writes into
    it; the same for one killed there) must not leave a lock without its content: a second
    writer would get 'cannot take its lock' instead of the holder's name, and after 2 s take
    the lock over while the first one still goes on (both writing). Exactly one wins; the
    other is refused with the winner's PID."""
    run = tmp_path / "run.h5"
    go = tmp_path / "go"
    go.write_text("")
    child = _child(run, "info", go)
    try:
        t_end = time.monotonic() + 60
        while not Path(str(run) + ".started").exists():
            assert child.poll() is None, child.communicate()
            assert time.monotonic() < t_end
            time.sleep(0.005)
        time.sleep(0.2)
        if lock_path(run).exists():  # published before its content was gathered: it must hold it
            assert read_lock(run) is not None, "an empty lock while its writer is stalled"
        mine = RunFileLock(run)
        try:
            mine.acquire()
        except FileInUse as exc:
            won_here = False
            assert f"being written by process {child.pid}" in str(exc), str(exc)
        else:
            won_here = True
        out, err = child.communicate(timeout=60)
        if won_here:
            assert out.startswith("refused:") and f"process {os.getpid()}" in out, out + err
            assert (read_lock(run) or {}).get("pid") == os.getpid()
            mine.release()
        else:
            assert out.startswith(f"won {child.pid}"), out + err
        assert not lock_path(run).exists()
    finally:
        child.kill()
        child.wait(10)


def test_processes_taking_over_one_stale_lock_at_once_give_one_winner(tmp_path: Path) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    run = tmp_path / "run.h5"
    lock_path(run).write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid}))
    go = tmp_path / "go"
    children = [_child(run, "stale", go) for _ in range(4)]
    try:
        time.sleep(1.0)  # the interpreters started and wait for the go
        go.write_text("")
        outs = [c.communicate(timeout=60) for c in children]
    finally:
        for c in children:
            c.kill()
            c.wait(10)
    lines = [o.strip() for o, _ in outs]
    winners = [line for line in lines if line.startswith("won")]
    assert len(winners) == 1, outs
    winner = int(winners[0].split()[1])
    for line in lines:
        assert line.startswith("won") or f"being written by process {winner}" in line, outs
    assert not lock_path(run).exists()


def test_a_lock_is_never_seen_empty_while_processes_race_for_it(tmp_path: Path) -> None:
    """Three processes take and release one lock 300 times each while this one reads it:
    whenever the lock exists it holds its whole content."""
    run = tmp_path / "run.h5"
    code = (
        "import sys\nfrom daq.store.lock import RunFileLock, FileInUse\n"
        "for _ in range(300):\n"
        "    lock = RunFileLock(sys.argv[1])\n"
        "    try:\n        lock.acquire()\n    except FileInUse:\n        continue\n"
        "    lock.release()\n"
    )
    procs = [subprocess.Popen([sys.executable, "-c", code, str(run)]) for _ in range(3)]
    seen = empty = 0
    try:
        while any(p.poll() is None for p in procs):
            try:
                raw = lock_path(run).read_bytes()
            except FileNotFoundError:
                continue
            seen += 1
            try:
                json.loads(raw)
            except ValueError:
                empty += 1
    finally:
        for p in procs:
            p.kill()
            p.wait(10)
    assert seen > 0 and empty == 0, f"{empty} of {seen} reads of the lock found it incomplete"
    assert not lock_path(run).exists()
    assert not list(tmp_path.glob(".*.tmp"))  # no temporary lock left behind


def test_an_old_empty_lock_is_taken_over_and_a_dead_writers_temporary_removed(
    tmp_path: Path,
) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    run = tmp_path / "run.h5"
    lock_path(run).write_bytes(b"")
    old = time.time() - 60
    os.utime(lock_path(run), (old, old))
    leftover = tmp_path / f".run.h5.lock.{dead.pid}-0a1b2c3d.tmp"
    leftover.write_text("{}")
    lock = RunFileLock(run).acquire()
    try:
        assert "empty or unreadable" in lock.stale_note
        assert (read_lock(run) or {}).get("pid") == os.getpid()
        assert not leftover.exists()
    finally:
        lock.release()
    assert not lock_path(run).exists()


def test_a_stale_lock_is_taken_over_where_the_file_system_refuses_flock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import fcntl

    def no_flock(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_flock)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    run = tmp_path / "run.h5"
    lock_path(run).write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid}))
    lock = RunFileLock(run).acquire()
    try:
        assert f"stale lock of process {dead.pid}" in lock.stale_note
        assert (read_lock(run) or {}).get("pid") == os.getpid()
    finally:
        lock.release()
