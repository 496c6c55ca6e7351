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


def test_a_folder_turned_read_only_at_the_end_keeps_the_outcome(  # type: ignore[no-untyped-def]
    proto: Path, tmp_path: Path, capsys, monkeypatch
) -> None:
    """A second reader remounted the output folder read-only mid-run: the lock's removal then
    raised, the outcome and the last line were lost to a traceback (exit 1 for a complete run,
    the file's status 'running'), and the log printed logging's traceback per message."""
    import errno

    from daq.store.lock import RunFileLock
    from protocols.runfile import read_run

    def read_only(self) -> None:  # type: ignore[no-untyped-def]
        raise OSError(errno.EROFS, "Read-only file system", str(self.lock))

    monkeypatch.setattr(RunFileLock, "release", read_only)
    out = tmp_path / "ro.h5"
    assert rp.main([str(proto), "--out", str(out), "-q"]) == 0
    captured = capsys.readouterr()
    assert captured.out.strip().startswith("complete: 12 points")
    assert "Traceback" not in captured.err
    assert read_run(out).status == "complete"
    assert "could not be removed (Read-only file system)" in log_path_for(out).read_text()


def test_a_log_file_that_cannot_be_written_is_said_once(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from daq.logsetup import hold_run_log

    class Broken:
        def write(self, text: str) -> None:
            raise OSError(28, "No space left on device")

        def flush(self) -> None:
            raise OSError(28, "No space left on device")

    h = hold_run_log(tmp_path / "full.h5")
    log = logging.getLogger(f"{LOGGER}.test")
    log.info("held")
    h.open_file()
    assert "held" in (tmp_path / "full.log").read_text()
    h._file.stream = Broken()  # type: ignore[union-attr]
    for i in range(3):
        log.info("message %d", i)
    err = capsys.readouterr().err
    assert err.count("cannot be written (No space left on device)") == 1, err
    assert "Traceback" not in err and "Logging error" not in err
    detach(h)
    blocked = tmp_path / "afile"
    blocked.write_text("")
    h = hold_run_log(blocked / "x.h5")  # its folder is a file: cannot be opened
    log.info("lost")
    h.open_file()
    assert "x.log cannot be written" in capsys.readouterr().err
    detach(h)
