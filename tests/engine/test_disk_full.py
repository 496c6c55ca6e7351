"""A full disk (:mod:`daq.store.disk_space`): a run that cannot fit is refused before anything
moves; a disk that fills during a run ends it, failed, every measured point kept; a records
write that fails anyway leaves that point pending and the file as a killed writer's.

Before, a run on a disk that filled went on: HDF5 dropped the records it could not write
(reported only as "exception ignored"), the points were marked measured over NaN records,
and the process crashed at its exit. The last two tests do that on a real full disk (a small
tmpfs), where this machine allows mounting one."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import daq.connect
from daq.cli import run_protocol as rp
from daq.engine import RunEngine
from daq.engine.outcome import ExitCode
from daq.request import RequestError, validate_request
from daq.store import disk_space
from daq.store.repair import repair_run
from protocols.left_open import files_left_open
from protocols.runfile import PointState, RunFileError, read_run

from .fakes import FakeWorld, fake_bench
from .helpers import PROTOCOL, fake_free_space

TESTS = Path(__file__).resolve().parents[1]
#: one point of PROTOCOL: 220 samples (2.2 ms at 100 kS/s), velocity and drive, float32
POINT = 2 * 4 * 220


def test_a_run_that_cannot_fit_is_refused_before_anything_moves(
    proto_file, tmp_path, monkeypatch, capsys
) -> None:
    need = 12 * POINT + disk_space.MARGIN_BYTES
    fake_free_space(monkeypatch, need - 1)
    with pytest.raises(RequestError) as exc:
        validate_request(proto_file, out=tmp_path / "r.h5")
    msg = str(exc.value)
    assert str(tmp_path / "r.h5") in msg and "12 point(s) need 16" in msg
    assert "disk has 16 MB free" in msg and "\n" not in msg
    monkeypatch.setattr(daq.connect, "connect_bench", lambda *a, **k: pytest.fail("connected"))
    assert rp.main([str(proto_file), "--out", str(tmp_path / "r.h5"), "--quiet"]) == 2
    assert not (tmp_path / "r.h5").exists()
    fake_free_space(monkeypatch, need)
    validate_request(proto_file, out=tmp_path / "r.h5")  # fits exactly


def test_a_resume_needs_room_for_its_pending_points_only(protocol, bench, out, monkeypatch) -> None:
    fake_free_space(monkeypatch, 10**12, 10**12, 0)  # full after the second point
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "failed" and res.n_measured_now == 2
    pending = 10 * POINT + disk_space.MARGIN_BYTES
    fake_free_space(monkeypatch, pending - 1)
    with pytest.raises(RequestError, match="10 point"):
        validate_request(protocol, bench, resume=out)
    fake_free_space(monkeypatch, pending)
    validate_request(protocol, bench, resume=out)


def test_a_disk_that_fills_during_a_run_ends_it_failed_with_every_point_kept(
    protocol, bench, out, tmp_path, monkeypatch
) -> None:
    calls = fake_free_space(
        monkeypatch, 10**12, 10**12, 10**12, disk_space.MARGIN_BYTES + POINT - 1
    )
    res = RunEngine(protocol, bench, fake_bench(FakeWorld(seed=3)), out, seed=3).run()
    assert res.status == "failed" and res.safe_state_s is not None
    assert "is full" in res.reason and "3 point(s) kept" in res.reason
    assert f"run_protocol --resume {out}" in res.reason
    assert res.n_measured_now == 3 and len(calls) == 4  # one look before each point
    run = read_run(out)
    assert run.status == "failed"
    fake_free_space(monkeypatch, 10**12)
    assert RunEngine(protocol, bench, fake_bench(FakeWorld(seed=3)), out, resume=True,
                     seed=3).run().status == "complete"  # fmt: skip
    full = tmp_path / "full.h5"
    RunEngine(protocol, bench, fake_bench(FakeWorld(seed=3)), full, seed=3).run()
    a, b = read_run(full), read_run(out)
    for d in ("ltr", "rtl"):
        np.testing.assert_array_equal(a.scans[d].velocity, b.scans[d].velocity)


def test_a_records_write_that_fails_leaves_the_point_pending_and_the_file_alone(
    protocol, bench, out, monkeypatch
) -> None:
    flushes: list[int] = []
    real_flush = h5py.Dataset.flush

    def flush(self: h5py.Dataset) -> None:  # the third point's velocity hits the full disk
        flushes.append(1)
        if len(flushes) == 5:
            raise RuntimeError("Unable to flush dataset (file write failed: errno = 28)")
        real_flush(self)

    monkeypatch.setattr(h5py.Dataset, "flush", flush)
    eng = RunEngine(protocol, bench, fake_bench(FakeWorld()), out)
    res = eng.run()
    assert res.status == "failed" and res.safe_state_s is not None
    assert "ltr amplitude #1 cylinder #3 could not be written" in res.reason
    assert "biafc repair" in res.reason and eng.file_broken == res.reason
    assert files_left_open() == (str(out),)  # the process must end without HDF5's clean-up
    monkeypatch.setattr(h5py.Dataset, "flush", real_flush)
    del eng  # the file as a killed writer leaves it: flags set, still 'running'
    report = repair_run(out)
    assert report.status_before == "running" and report.n_done == 2
    run = read_run(out)
    assert run.scans["ltr"].done[0, 2] == PointState.PENDING


def test_a_run_whose_file_cannot_be_closed_is_not_complete(
    protocol, bench, out, monkeypatch
) -> None:
    """Every point measured, but the final status could not be written (the disk filled at the
    end): the file says 'running' until ``biafc repair``, so the run is not reported complete
    (it was, exit 0)."""
    from protocols.runfile import RunFileError, RunFileWriter

    def close(self: RunFileWriter, status: str, **k: object) -> None:
        self.broken = f"{self.path}: the file could not be closed (file write failed)"
        raise RunFileError(self.broken)

    monkeypatch.setattr(RunFileWriter, "close", close)
    eng = RunEngine(protocol, bench, fake_bench(FakeWorld()), out)
    res = eng.run()
    assert res.n_measured_now == 12 and res.safe_state_s is not None
    assert res.status == "failed" and "could not be closed" in res.reason
    assert eng.file_broken is not None


# -- a real full disk ------------------------------------------------------------------------
def _tmpfs(folder: Path, size: str) -> bool:
    folder.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                              capture_output=True, timeout=10)  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


@pytest.fixture
def small_disk(tmp_path: Path):  # type: ignore[no-untyped-def]
    """A 24 MB file system of its own, or a skip where this machine cannot mount one."""
    disk = tmp_path / "disk"
    if sys.platform != "linux" or not _tmpfs(disk, "24m"):
        pytest.skip("mounting a small tmpfs needs Linux and the right to mount (root)")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True, timeout=30)


#: the fake run_protocol with the disk checks off: what a disk that fills between the check
#: and the write (another process writing) does
_UNCHECKED = r"""
import runpy, sys
import daq.engine.engine as engine
engine.room_for_a_point = lambda *a, **k: None
sys.argv[0] = "fake_cli"
runpy.run_module("engine.fake_cli", run_name="__main__")
"""


def _run(args: list[str], *, checked: bool) -> subprocess.Popen[str]:
    env = dict(os.environ, FAKE_READ_S="0.02", PYTHONPATH=str(TESTS))
    cmd = ["-m", "engine.fake_cli"] if checked else ["-c", _UNCHECKED]
    return subprocess.Popen([sys.executable, *cmd, *args], cwd=TESTS, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


def _a_point_in(out: Path) -> bool:
    """Whether the live file ``out`` holds a measured point yet. A read racing the writer's
    flush on a loaded host may fail ("address of object past end of allocation", seen once in
    about ten runs beside two busy processes): that counts as not yet, and is read again."""
    try:
        return out.exists() and bool(read_run(out).scans["ltr"].done.any())
    except RunFileError:
        return False


def _fill_after_a_point(disk: Path, out: Path, proc: subprocess.Popen[str], keep: int) -> None:
    """Once a point is in ``out``, fill ``disk`` to ``keep`` bytes free (another writer)."""
    t_end = time.monotonic() + 60
    while not _a_point_in(out):
        assert proc.poll() is None and time.monotonic() < t_end, proc.communicate()
        time.sleep(0.02)
    with open(disk / "filler", "wb") as f:
        try:
            while (free := os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize) > keep:
                f.write(b"\0" * min(free - keep, 1 << 20))
                f.flush()
        except OSError:  # full
            pass


def test_a_real_disk_that_fills_ends_the_run_failed_every_point_kept(small_disk, tmp_path) -> None:
    proto = tmp_path / "long.yaml"
    proto.write_text(PROTOCOL.replace("duration: 2 ms", "duration: 200 ms"))  # 160 kB a point
    out = small_disk / "r.h5"
    proc = _run([str(proto), "--out", str(out)], checked=True)
    _fill_after_a_point(small_disk, out, proc, keep=disk_space.MARGIN_BYTES // 2)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == ExitCode.FAILED, stderr
    assert "is full" in stderr.strip().splitlines()[-1]
    run = read_run(out)
    kept = run.scans["ltr"].done == PointState.DONE
    assert run.status == "failed" and kept.any()
    assert np.isfinite(run.scans["ltr"].velocity[kept]).all()


def test_a_write_on_a_full_disk_fails_the_run_with_exit_1_and_a_repairable_file(
    small_disk, tmp_path
) -> None:
    """Before: the points went on being marked measured over NaN records, and the process
    crashed at its exit (status 139)."""
    proto = tmp_path / "long.yaml"
    proto.write_text(PROTOCOL.replace("duration: 2 ms", "duration: 200 ms"))
    out = small_disk / "r.h5"
    proc = _run([str(proto), "--out", str(out)], checked=False)
    _fill_after_a_point(small_disk, out, proc, keep=0)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == ExitCode.FAILED, stderr
    assert "could not be written" in stderr.strip().splitlines()[-1]
    (small_disk / "filler").unlink()
    report = repair_run(out)
    run = read_run(out)
    kept = run.scans["ltr"].done == PointState.DONE
    assert report.n_done == int(kept.sum()) >= 1
    assert np.isfinite(run.scans["ltr"].velocity[kept]).all()
