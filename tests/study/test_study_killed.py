"""A ``biafc study`` process killed (SIGKILL) at any moment: every task a reader saw written is
still there, the same command continues it to exactly the uninterrupted numbers, ``biafc
repair`` makes the killed output readable by plain h5py, and a second writer is refused."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli.biafc import main
from daq.store.lock import lock_path
from protocols.studyfile import StudyFileError, read_study

from .conftest import TINY

ROOT = Path(__file__).resolve().parents[2]

#: the tiny study in 60 one-cell tasks (~25 ms each): room to kill the writer between tasks
MANY = (
    TINY.replace("count: 3}", "count: 6}")
    .replace("[3 N, 6 N]", "[3 N, 4 N, 5 N, 6 N, 7 N]")
    .replace("cells_per_task: 3", "cells_per_task: 1")
)


@pytest.fixture(scope="module")
def many(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The study file and its uninterrupted serial output (the reference)."""
    d = tmp_path_factory.mktemp("many")
    study = d / "many.yaml"
    study.write_text(MANY)
    ref = d / "reference.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(ref), "-q"]) == 0
    return study, ref


def _spawn(study: Path, out: Path) -> subprocess.Popen[str]:
    args = ["study", str(study), "--workers", "0", "--out", str(out), "-q"]
    return subprocess.Popen(
        [sys.executable, "-m", "daq.cli.biafc", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _done_cells(out: Path) -> int:
    try:
        return int(np.sum(read_study(out, spectra=False).status != 0))
    except (StudyFileError, OSError, KeyError):  # not made yet, or caught mid-flush
        return 0


def _killed_study(study: Path, out: Path, at_least: int) -> tuple[int, dict[str, np.ndarray]]:
    """Run the study in a subprocess, SIGKILL it once a reader sees ``at_least`` cells written;
    return its PID and what a reader saw (status and metrics) just before the kill."""
    proc = _spawn(study, out)
    t_end = time.monotonic() + 120
    while _done_cells(out) < at_least:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < t_end, "no task written in 120 s"
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGSTOP)  # freeze it wherever it is (mid-write included) ...
    seen = read_study(out, spectra=False)
    proc.kill()  # ... and kill it there
    proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    return proc.pid, {"status": seen.status, **seen.metrics}


def _same(a: Path, b: Path) -> None:
    ra, rb = read_study(a), read_study(b)
    assert ra.metrics.keys() == rb.metrics.keys()
    for name in ra.metrics:
        assert np.array_equal(ra.metrics[name], rb.metrics[name], equal_nan=True), name
    assert np.array_equal(ra.status, rb.status)


def _plain_h5py_opens(p: Path) -> bool:
    try:
        with h5py.File(p, "r") as f:
            return bool(f.attrs["format"] == "biafc-study")
    except OSError:
        return False


def test_a_killed_study_keeps_every_written_task_and_the_same_command_completes_it_the_same(
    many: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study, ref = many
    out = tmp_path / "killed.h5"
    _, seen = _killed_study(study, out, at_least=3)
    n_seen = int(np.sum(seen["status"] != 0))
    after = read_study(out, spectra=False)  # a killed output reads without a repair
    assert after.attrs["status"] == "running" and lock_path(out).exists()
    kept = seen["status"] != 0
    assert 3 <= n_seen < after.n_cells  # killed mid-study
    assert np.array_equal(after.status[kept], seen["status"][kept])
    for name, arr in after.metrics.items():
        assert np.array_equal(arr[kept], seen[name][kept], equal_nan=True), name
        assert np.all(np.isfinite(arr[after.status == 1])), name  # no half-written task
    # the same command continues it (taking over the dead writer's lock) ...
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    assert f"continuing: {int(np.sum(after.status != 0))} of 60 cells done already" in err
    # ... to exactly the uninterrupted numbers
    _same(ref, out)
    assert read_study(out).attrs["status"] == "complete" and not lock_path(out).exists()
    assert _plain_h5py_opens(out)


def test_repair_makes_a_killed_study_readable_by_plain_h5py_without_losing_a_cell(
    many: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study, ref = many
    out = tmp_path / "killed.h5"
    pid, _ = _killed_study(study, out, at_least=1)
    before = read_study(out, spectra=False)
    assert not _plain_h5py_opens(out)  # "file is already open for write"
    assert main(["repair", str(out)]) == 0
    line = capsys.readouterr().out
    assert "cleared the open-for-write flags" in line and "incomplete" in line, line
    assert f"process {pid}" in line and "cell(s) run" in line  # the stale lock, taken over
    assert _plain_h5py_opens(out) and not lock_path(out).exists()
    repaired = read_study(out, spectra=False)
    assert repaired.attrs["status"] == "incomplete"
    assert np.array_equal(repaired.status, before.status)
    for name in before.metrics:
        assert np.array_equal(repaired.metrics[name], before.metrics[name], equal_nan=True)
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 0
    _same(ref, out)


def test_a_second_study_writing_the_same_output_is_refused_in_one_line(
    many: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study, _ = many
    out = tmp_path / "busy.h5"
    proc = _spawn(study, out)
    try:
        t_end = time.monotonic() + 120
        # the lock is published whole (daq.store.lock), so once it exists it names its
        # writer, whatever moment the writer is stopped at
        while not lock_path(out).exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < t_end
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGSTOP)  # the writer holds the file for as long as we check
        before = out.read_bytes() if out.exists() else b""
        code = main(["study", str(study), "--workers", "0", "--out", str(out), "-q"])
        err = capsys.readouterr().err
        assert code == 2
        assert len(err.strip().splitlines()) == 1, err
        assert f"is being written by process {proc.pid}" in err and str(out) in err
        assert (out.read_bytes() if out.exists() else b"") == before
    finally:
        proc.kill()
        proc.wait(10)
