"""``run_protocol``: bad input refused in one line before anything moves; dry run; crash safety
(SIGKILL, then --resume) and Ctrl-C, on the fake instruments in a subprocess."""

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

import daq.connect
from daq.cli import run_protocol as rp
from protocols.runfile import PointState, read_run
from protocols.swmr_read import open_swmr

from .fakes import FakeWorld, fake_bench
from .helpers import PROTOCOL

TESTS = Path(__file__).resolve().parents[1]


@pytest.fixture
def no_instruments(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    calls: list[int] = []

    def forbidden(*a: object, **k: object) -> None:
        calls.append(1)
        raise AssertionError("an instrument was opened")

    monkeypatch.setattr(daq.connect, "connect_bench", forbidden)
    return calls


def _main_err(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    code = rp.main(args)
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    return err


def test_existing_output_is_refused(proto_file, tmp_path, capsys, no_instruments) -> None:
    out = tmp_path / "run.h5"
    out.write_bytes(b"x")
    err = _main_err([str(proto_file), "--out", str(out)], capsys)
    assert "exists already and is not a run file" in err and "--resume" not in err
    assert f"--out {tmp_path / 'run_2.h5'}" in err
    assert out.read_bytes() == b"x" and not no_instruments


def test_unwritable_output_is_refused(
    proto_file, tmp_path, capsys, no_instruments, monkeypatch
) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    real_access = os.access
    if real_access(ro, os.W_OK):  # root writes anywhere: let the folder say no
        monkeypatch.setattr(
            os, "access", lambda p, m: False if Path(p) == ro else real_access(p, m)
        )
    try:
        err = _main_err([str(proto_file), "--out", str(ro / "sub" / "run.h5")], capsys)
        assert "cannot write in" in err and str(ro) in err
    finally:
        ro.chmod(0o700)


def test_output_under_a_file_is_refused(proto_file, tmp_path, capsys, no_instruments) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    err = _main_err([str(proto_file), "--out", str(blocker / "run.h5")], capsys)
    assert "cannot write" in err and not no_instruments


def test_bad_protocol_is_one_line(tmp_path, capsys, no_instruments) -> None:
    f = tmp_path / "p.yaml"
    f.write_text(PROTOCOL.replace("averages: 2", "averages: 2\ncolour: red"))
    err = _main_err([str(f), "--out", str(tmp_path / "o.h5")], capsys)
    assert "colour: unknown key 'colour'" in err and f"{f}:" in err
    assert not (tmp_path / "o.h5").exists() and not no_instruments


def test_missing_resume_file(proto_file, tmp_path, capsys, no_instruments) -> None:
    assert "does not exist" in _main_err(
        [str(proto_file), "--resume", str(tmp_path / "n.h5")], capsys
    )


def test_dry_run_prints_points_and_eta(proto_file, tmp_path, capsys, no_instruments) -> None:
    assert rp.main([str(proto_file), "--dry-run", "--out", str(tmp_path / "o.h5")]) == 0
    out = capsys.readouterr().out
    assert "12 points" in out and "estimated" in out
    assert not (tmp_path / "o.h5").exists() and not no_instruments


def test_cli_run_in_process(proto_file, tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setattr(daq.connect, "connect_bench", lambda bf, **k: fake_bench(FakeWorld()))
    out = tmp_path / "o.h5"
    assert rp.main([str(proto_file), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "point 12/12" in text and "complete: 12 points" in text
    assert read_run(out).status == "complete"


def _spawn(args: list[str], read_s: float = 0.05) -> subprocess.Popen[str]:
    env = dict(os.environ, FAKE_READ_S=str(read_s), PYTHONPATH=str(TESTS))
    return subprocess.Popen(
        [sys.executable, "-m", "engine.fake_cli", *args],
        cwd=TESTS,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_done(path: Path, n: int, proc: subprocess.Popen[str], timeout_s: float = 60) -> int:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        assert proc.poll() is None, proc.communicate()
        if path.exists():
            try:
                with open_swmr(path) as f:
                    got = int(np.sum(f["scan/ltr/done"][...] == PointState.DONE))
                if got >= n:
                    return got
            except (OSError, KeyError):
                pass
        time.sleep(0.05)
    raise AssertionError("the run made no progress")


def test_sigkill_then_resume_equals_an_uninterrupted_run(proto_file, tmp_path, monkeypatch) -> None:
    killed = tmp_path / "killed.h5"
    proc = _spawn([str(proto_file), "--out", str(killed), "--seed", "5"])
    _wait_done(killed, 2, proc)
    proc.kill()
    proc.wait(10)
    part = read_run(killed)  # readable, completed points intact
    assert part.status == "running"
    n_done = int(sum(np.sum(s.done == PointState.DONE) for s in part.scans.values()))
    assert 2 <= n_done < 12
    for s in part.scans.values():
        measured = s.done == PointState.DONE
        assert np.all(np.isfinite(s.velocity[measured]))
        assert np.all(np.isnan(s.velocity[~measured]))
    monkeypatch.setattr(
        daq.connect,
        "connect_bench",
        lambda bf, seed=None, **k: fake_bench(FakeWorld(seed=seed or 0)),
    )
    assert rp.main([str(proto_file), "--resume", str(killed), "--quiet"]) == 0  # seed from the file
    full = tmp_path / "full.h5"
    assert rp.main([str(proto_file), "--out", str(full), "--seed", "5", "--quiet"]) == 0
    a, b = read_run(full), read_run(killed)
    assert b.status == "complete" and b.attrs["seed"] == 5
    for d in ("ltr", "rtl"):
        np.testing.assert_array_equal(a.scans[d].done, b.scans[d].done)
        np.testing.assert_array_equal(a.scans[d].velocity, b.scans[d].velocity)
    assert any("resumed" in m for _, _, m in b.log)


def test_sigint_aborts_safely(proto_file, tmp_path) -> None:
    out = tmp_path / "int.h5"
    proc = _spawn([str(proto_file), "--out", str(out)])
    _wait_done(out, 1, proc)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 130, stderr
    assert "run aborted: interrupted by SIGINT" in stderr
    assert "OUTPUTS {1: False, 2: False}" in stdout
    run = read_run(out)
    assert run.status == "aborted"
    assert any("aborted" in m for _, _, m in run.log)


def test_sigterm_aborts_safely(proto_file, tmp_path) -> None:
    out = tmp_path / "term.h5"
    proc = _spawn([str(proto_file), "--out", str(out)])
    _wait_done(out, 1, proc)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 1, stderr
    assert "OUTPUTS {1: False, 2: False}" in stdout
    assert read_run(out).status == "aborted"


def _run_in_a_terminal(args: list[str], outputs: Path, *, nohup: bool) -> tuple[int, float]:
    """Run the fake ``run_protocol`` on a pseudo-terminal, close the terminal once a point is
    measured (as a closed window or a dropped ssh link does: the kernel sends SIGHUP), and
    return its exit status and the seconds it took after the hangup. ``nohup``: SIGHUP ignored,
    as ``nohup`` starts it."""
    import pty
    import threading

    env = dict(os.environ, FAKE_READ_S="0.05", PYTHONPATH=str(TESTS))
    env["FAKE_OUTPUTS_FILE"] = str(outputs)
    pid, fd = pty.fork()
    if pid == 0:  # the child: its session's controlling terminal is the pty
        try:
            os.chdir(TESTS)
            if nohup:  # as nohup does: SIGHUP ignored, the output to nohup.out
                signal.signal(signal.SIGHUP, signal.SIG_IGN)
                log = os.open(outputs.with_name("nohup.out"), os.O_WRONLY | os.O_CREAT, 0o644)
                os.dup2(log, 1)
                os.dup2(log, 2)
            os.execve(sys.executable, [sys.executable, "-m", "engine.fake_cli", *args], env)
        finally:
            os._exit(127)

    def drain() -> None:  # the terminal shows what the run writes
        try:
            while os.read(fd, 4096):
                pass
        except OSError:
            pass

    threading.Thread(target=drain, daemon=True).start()
    out = Path(args[args.index("--out") + 1])
    t_end = time.monotonic() + 60
    while time.monotonic() < t_end:
        try:
            with open_swmr(out) as f:
                if int(np.sum(f["scan/ltr/done"][...] == PointState.DONE)) >= 1:
                    break
        except (OSError, KeyError):
            pass
        time.sleep(0.05)
    os.close(fd)  # the terminal goes away
    hung_up = time.monotonic()
    while time.monotonic() < hung_up + 60:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status), time.monotonic() - hung_up
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    raise AssertionError("run_protocol did not end after its terminal closed")


@pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="no terminal hangup on this platform")
def test_a_closed_terminal_aborts_safely(proto_file, tmp_path) -> None:
    """Before, SIGHUP killed the process where it stood: the generator's outputs left on, the
    file 'running' with its lock, the log cut off."""
    out, outputs = tmp_path / "hup.h5", tmp_path / "outputs.txt"
    code, after_s = _run_in_a_terminal([str(proto_file), "--out", str(out)], outputs, nohup=False)
    assert code == 1  # aborted, safe state confirmed (3 if unconfirmed)
    assert outputs.read_text() == "OUTPUTS {1: False, 2: False}\n"
    run = read_run(out)
    assert run.status == "aborted"
    assert any("interrupted by SIGHUP" in m for _, _, m in run.log)
    log = out.with_suffix(".log").read_text(encoding="utf-8")
    assert "run aborted: interrupted by SIGHUP" in log and "safe state confirmed" in log
    assert not (tmp_path / "hup.h5.lock").exists()
    assert after_s < 10


@pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="no terminal hangup on this platform")
def test_under_nohup_a_closed_terminal_lets_the_run_finish(proto_file, tmp_path) -> None:
    out, outputs = tmp_path / "nohup.h5", tmp_path / "outputs.txt"
    code, _ = _run_in_a_terminal([str(proto_file), "--out", str(out)], outputs, nohup=True)
    assert code == 0
    assert outputs.read_text() == "OUTPUTS {1: False, 2: False}\n"
    assert read_run(out).status == "complete"
    assert "complete: " in (tmp_path / "nohup.out").read_text(encoding="utf-8")


def test_lookup3_matches_hdf5_superblock_checksum(tmp_path: Path) -> None:
    import struct

    from daq.store.recover import clear_consistency_flags, lookup3

    f = tmp_path / "x.h5"
    with h5py.File(f, "w", libver="latest") as h:
        h["a"] = [1, 2]
    raw = f.read_bytes()
    n = 12 + 4 * raw[9]
    assert lookup3(raw[:n]) == struct.unpack_from("<I", raw, n)[0]
    assert clear_consistency_flags(f) is False  # a cleanly closed file has no flags set
    assert f.read_bytes() == raw


def test_resume_alone_takes_protocol_and_bench_from_the_file(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    """``run_protocol --resume RUN.h5`` (no protocol argument) continues a killed run."""
    killed = tmp_path / "killed.h5"
    proc = _spawn([str(proto_file), "--out", str(killed), "--seed", "3"])
    _wait_done(killed, 2, proc)
    proc.kill()
    proc.wait(10)
    proto_file.unlink()  # the protocol file is gone: the run file holds it
    monkeypatch.setattr(
        daq.connect,
        "connect_bench",
        lambda bf, seed=None, **k: fake_bench(FakeWorld(seed=seed or 0)),
    )
    assert rp.main(["--resume", str(killed), "--dry-run"]) == 0
    assert "'fake_scan'" in capsys.readouterr().out
    assert rp.main(["--resume", str(killed)]) == 0
    out = capsys.readouterr().out
    assert "complete: 12 points" in out
    run = read_run(killed)
    assert run.status == "complete"
    assert all(np.all(s.done == PointState.DONE) for s in run.scans.values())


def test_no_protocol_and_no_resume_is_one_line(tmp_path, capsys, no_instruments) -> None:
    err = _main_err([], capsys)
    assert "give a protocol" in err and "--resume RUN.h5" in err and "smoke" in err


def test_resume_alone_of_a_file_that_is_not_a_run(tmp_path, capsys, no_instruments) -> None:
    bogus = tmp_path / "bogus.h5"
    h5py.File(bogus, "w").close()
    err = _main_err(["--resume", str(bogus)], capsys)
    assert err.startswith("run_protocol: error: --resume:") and "not a biafc run file" in err


def _finished_run(path: Path, status: str) -> None:
    from protocols.runfile import FORMAT

    with h5py.File(path, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = 1
        f.attrs["status"] = status


def test_out_of_a_complete_run_suggests_a_free_name(
    proto_file, tmp_path, capsys, no_instruments
) -> None:
    out = tmp_path / "run.h5"
    _finished_run(out, "complete")
    (tmp_path / "run_2.h5").write_bytes(b"")
    err = _main_err([str(proto_file), "--out", str(out)], capsys)
    assert "is a complete run already" in err
    assert f"--out {tmp_path / 'run_3.h5'}" in err and "--resume" not in err


def test_out_of_an_interrupted_run_suggests_resume(
    proto_file, tmp_path, capsys, no_instruments
) -> None:
    out = tmp_path / "run.h5"
    _finished_run(out, "aborted")
    err = _main_err([str(proto_file), "--out", str(out)], capsys)
    assert f"continue it with --resume {out}" in err and "left aborted" in err


def test_resume_of_a_complete_run_is_refused_before_connecting(
    proto_file, tmp_path, capsys, no_instruments
) -> None:
    out = tmp_path / "run.h5"
    _finished_run(out, "complete")
    err = _main_err([str(proto_file), "--resume", str(out)], capsys)
    assert "complete already, nothing to continue" in err and "--out" in err
    assert "unexpected" not in err and not no_instruments


def test_out_folder_takes_the_protocols_file_name(proto_file, tmp_path, capsys) -> None:
    folder = tmp_path / "runs"
    folder.mkdir()
    assert rp.main([str(proto_file), "--out", str(folder), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert f"output {folder}/fake_scan_" in out and out.strip().endswith(".h5")


def test_out_under_a_file_names_it(proto_file, tmp_path, capsys, no_instruments) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    err = _main_err([str(proto_file), "--out", str(blocker / "run.h5")], capsys)
    assert f"{blocker} is a file, not a folder" in err


def test_homing_is_said_with_its_longest_time_before_the_first_point(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """On the rig homing takes minutes before the first point, and the terminal said nothing
    (the window showed it, the command line did not print the status). The stage's travel at
    its homing speed bounds it: 500 mm at 25 mm/s on the simulated bench."""
    assert rp.main(["smoke", "--out", str(tmp_path / "h.h5")]) == 0
    text = capsys.readouterr().out
    first = text.splitlines()[0]
    assert first == "homing the stage (at most 20 s)", text
    log = (tmp_path / "h.log").read_text(encoding="utf-8")
    assert "biafc.run: homing the stage (at most 20 s)" in log
