"""A run file's final status is written although a reader holds the file at that moment
(:mod:`protocols.finish_open`). The writer closes the SWMR file and opens it again to set the
status. A reader following the run holds HDF5's shared lock while it reads, and the reopen then
failed ("unable to lock file"): the file said ``running`` while the run was reported complete."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

import protocols.finish_open
from daq.engine import RunEngine
from protocols.runfile import RunFileWriter, read_run

from .fakes import FakeWorld, fake_bench

#: a reader that opens the run file (as a live run is read: SWMR) and holds it for argv[2] s
_READER = r"""
import sys, time
from protocols.swmr_read import open_swmr
with open_swmr(sys.argv[1]) as f:
    print("reading", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _with_a_reader(monkeypatch: pytest.MonkeyPatch, hold_s: float) -> list[float]:
    """Each run file's close starts while a reader process holds the file; returns how long
    the closes took (s)."""
    real_close = RunFileWriter.close
    took: list[float] = []

    def close(self: RunFileWriter, status: str, **k: object) -> None:
        self._f.flush()
        reader = subprocess.Popen([sys.executable, "-c", _READER, str(self.path), str(hold_s)],
                                  stdout=subprocess.PIPE, text=True)  # fmt: skip
        assert reader.stdout is not None and reader.stdout.readline().strip() == "reading"
        t0 = time.monotonic()
        try:
            real_close(self, status, **k)  # type: ignore[arg-type]
        finally:
            took.append(time.monotonic() - t0)
            reader.kill()
            reader.wait(10)

    monkeypatch.setattr(RunFileWriter, "close", close)
    return took


def test_the_final_status_waits_for_a_reader_and_is_written(
    protocol, bench, out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    took = _with_a_reader(monkeypatch, hold_s=0.5)
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "complete", res.reason
    assert read_run(out).status == "complete"
    assert 0.3 < took[0] < protocols.finish_open.READERS_WAIT_S


def test_a_reader_that_stays_does_not_keep_the_status_from_being_written(
    protocol, bench, out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(protocols.finish_open, "READERS_WAIT_S", 0.3)
    took = _with_a_reader(monkeypatch, hold_s=30.0)
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "complete", res.reason
    assert read_run(out).status == "complete"
    assert took[0] < 5.0
