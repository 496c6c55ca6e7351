"""One logging setup (daq.logsetup) for the command line and the window: -v/-q, and a log file
beside the run file that keeps what happened (appended on --resume)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

import daq.connect
from daq.cli import run_protocol as rp
from daq.logsetup import LOGGER, attach_run_log, configure, detach, log_path_for

from .fakes import FakeWorld, fake_bench
from .helpers import PROTOCOL


@pytest.fixture
def proto(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setattr(daq.connect, "connect_bench", lambda bf, **k: fake_bench(FakeWorld()))
    f = tmp_path / "p.yaml"
    f.write_text(PROTOCOL)
    yield f
    configure(0)  # leave the terminal handler as a fresh process has it


def test_log_file_beside_the_run_file(proto: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "runs" / "scan.h5"
    assert rp.main([str(proto), "--out", str(out)]) == 0
    log = (tmp_path / "runs" / "scan.log").read_text()
    assert "biafc.run: run started: protocol 'fake_scan', 12 points" in log
    assert "generator channel 1: ltr burst" in log
    assert "biafc.run_protocol: complete: 12 points" in log and "(exit 0)" in log
    assert rp.main(["--resume", str(out)]) == 2  # complete: refused before anything starts
    assert log_path_for(out) == tmp_path / "runs" / "scan.log"
    handlers = logging.getLogger(LOGGER).handlers
    assert not [h for h in handlers if isinstance(h, logging.FileHandler)]  # removed at the end


def test_verbose_and_quiet(proto: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert rp.main([str(proto), "--out", str(tmp_path / "a.h5")]) == 0
    default = capsys.readouterr()
    assert "generator channel" not in default.err and "point 12/12" in default.out
    assert rp.main([str(proto), "--out", str(tmp_path / "b.h5"), "-v"]) == 0
    verbose = capsys.readouterr()
    assert "biafc.run: INFO: generator channel 1: ltr burst" in verbose.err
    assert rp.main([str(proto), "--out", str(tmp_path / "c.h5"), "-q"]) == 0
    quiet = capsys.readouterr()
    assert "point 12/12" not in quiet.out and quiet.err == ""
    assert len(quiet.out.strip().splitlines()) == 1
    assert quiet.out.strip().startswith("complete: 12 points")


def test_resume_appends_to_the_same_log(tmp_path: Path) -> None:
    run = tmp_path / "r.h5"
    for text in ("first", "second"):
        h = attach_run_log(run)
        logging.getLogger(f"{LOGGER}.test").info(text)
        detach(h)
    lines = log_path_for(run).read_text().splitlines()
    assert [ln.rsplit(": ", 1)[1] for ln in lines] == ["first", "second"]
