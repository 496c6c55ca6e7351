"""One process at a time on a lab bench's instruments (:mod:`daq.instrument_lock`): a second
process is refused before it opens anything, naming the instrument and the process holding it;
the holder's closing, or its death, frees them; a simulated bench takes no lock.

Before, a second process connected the same rig without a word: on Linux a serial port opens
twice, and VISA shares an instrument between sessions, so its commands mixed with a running
scan's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import daq.connect
from daq.cli import run_protocol as rp
from daq.connect import ConnectError, connect_bench
from protocols.bench import default_bench_path, load_bench

from .helpers import cable_lab_bench

LAB = default_bench_path().parent / "lab_bench.yaml"
ROOT = Path(__file__).resolve().parents[2]

#: another process: connects the lab bench (its cables to a simulated rig), says so, waits
_HOLDER = r"""
import sys, time
import pytest
from engine.helpers import cable_lab_bench
from daq.connect import connect_bench
cable_lab_bench(pytest.MonkeyPatch())
bench = connect_bench(sys.argv[1])
print("connected", flush=True)
time.sleep(60)
"""


@pytest.fixture
def cables(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[tuple[str, str, float]]:
    """The lab bench cabled to a simulated rig (:func:`helpers.cable_lab_bench`), the locks in
    a fresh cache folder; returns the transports opened, in order."""
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path / "cache"))
    return cable_lab_bench(monkeypatch)


def _locks(tmp_path: Path) -> list[str]:
    folder = tmp_path / "cache" / "instruments"
    return sorted(p.name for p in folder.glob("*.lock")) if folder.exists() else []


def _holder(tmp_path: Path) -> subprocess.Popen[str]:
    env = dict(os.environ, BIAFC_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT / "tests"))
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(LAB)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "connected", proc.communicate()
    return proc


def test_a_second_process_is_refused_the_instruments_of_a_connected_bench(
    cables: list[tuple[str, str, float]], tmp_path: Path
) -> None:
    holder = _holder(tmp_path)
    try:
        with pytest.raises(ConnectError) as exc:
            connect_bench(LAB)
    finally:
        holder.kill()
        holder.wait(10)
    msg = str(exc.value)
    generator = load_bench(LAB).bench.generator.resource
    assert f"the generator {generator} is in use by process {holder.pid}" in msg
    assert "\n" not in msg and "wait for it to end or stop it" in msg
    assert cables == []  # nothing opened
    bench = connect_bench(LAB)  # the holder is gone: its locks are stale, taken over
    assert [name for name, _, _ in cables] == ["generator", "vibrometer", "stage"]
    bench.close()
    assert _locks(tmp_path) == []


def test_run_protocol_on_a_bench_in_use_is_refused_with_exit_2(
    cables: list[tuple[str, str, float]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    holder = _holder(tmp_path)
    try:
        code = rp.main(["smoke.yaml", "--bench", str(LAB), "--out", str(tmp_path / "r.h5"), "-q"])
    finally:
        holder.kill()
        holder.wait(10)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "is in use by process" in err[-1]
    assert cables == [] and not (tmp_path / "r.h5").exists()


def test_biafc_check_on_a_bench_in_use_is_refused_with_exit_2(
    cables: list[tuple[str, str, float]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from daq.cli.biafc import main

    holder = _holder(tmp_path)
    try:
        code = main(["check", str(LAB), "--move"])
    finally:
        holder.kill()
        holder.wait(10)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("biafc check: refused: the generator")
    assert cables == []  # no burst, no move: nothing opened


def test_one_process_may_connect_again_and_the_last_close_frees_the_instruments(
    cables: list[tuple[str, str, float]], tmp_path: Path
) -> None:
    a = connect_bench(LAB)
    b = connect_bench(LAB)  # the bench window reconnecting, say
    assert len(_locks(tmp_path)) == 4  # generator, vibrometer, stage, DAQ device
    a.close()
    assert len(_locks(tmp_path)) == 4
    b.close()
    b.close()  # twice: no harm
    assert _locks(tmp_path) == []


def test_a_cache_folder_that_cannot_be_written_is_one_line_before_anything_opens(
    cables: list[tuple[str, str, float]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(blocker / "cache"))
    with pytest.raises(ConnectError, match="cannot lock the bench's instruments") as exc:
        connect_bench(LAB)
    assert "BIAFC_CACHE_DIR" in str(exc.value) and "\n" not in str(exc.value)
    assert cables == []


def test_a_simulated_bench_takes_no_lock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path / "cache"))
    a, b = connect_bench(), connect_bench()  # each its own emulated rig
    assert _locks(tmp_path) == []
    a.close()
    b.close()


def test_a_failed_connection_lets_its_locks_go(
    cables: list[tuple[str, str, float]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def dead(*a: Any, **k: Any) -> Any:
        raise ConnectError("the vibrometer does not answer")

    monkeypatch.setattr(daq.connect, "build_drivers", dead)
    with pytest.raises(ConnectError, match="does not answer"):
        connect_bench(LAB)
    assert _locks(tmp_path) == []


def test_one_device_named_two_ways_is_one_lock(
    cables: list[tuple[str, str, float]], tmp_path: Path
) -> None:
    """A second reader: the locks went by the address text, so ``ASRL3::INSTR`` beside
    ``COM3`` (or ``Dev1`` beside ``dev1``) let two processes drive one port or card."""
    from daq.instrument_lock import canonical

    assert canonical("ASRL3::INSTR") == canonical("COM3") == canonical("asrl3")
    assert canonical("ASRL/dev/ttyUSB0::INSTR") == canonical("/dev/ttyUSB0")
    assert canonical("Dev1") == canonical("dev1") and canonical("/dev/ttyUSB0") != "/DEV/TTYUSB0"
    holder = _holder(tmp_path)
    try:
        text = (
            LAB.read_text()
            .replace("TCPIP0::192.168.1.10::INSTR", "TCPIP0::192.168.1.11::INSTR")
            .replace("resource: ASRL3::INSTR", "resource: ASRL7::INSTR")
            .replace("resource: ASRL4::INSTR", "resource: COM4")  # the holder's stage
        )
        other = tmp_path / "other.yaml"
        other.write_text(text)
        with pytest.raises(ConnectError, match="stage COM4 is in use by process"):
            connect_bench(other)
    finally:
        holder.kill()
        holder.wait(10)


def test_a_lan_or_usb_generator_is_one_lock_whatever_its_spelling(
    cables: list[tuple[str, str, float]], tmp_path: Path
) -> None:
    """A reviewer: the LAN generator, where a lock matters most (a 33500B takes several LAN
    sessions), took one lock per spelling of its address; one bench file naming one device
    for two roles is refused."""
    from daq.instrument_lock import InstrumentInUse, canonical, lock_instruments

    lan = {
        canonical(a)
        for a in (
            "TCPIP0::192.168.1.10::INSTR",
            "TCPIP::192.168.1.10::INSTR",
            "TCPIP0::192.168.1.10::inst0::INSTR",
            "TCPIP0::192.168.1.10::hislip0::INSTR",
            "TCPIP0::192.168.1.10::5025::SOCKET",
        )
    }
    assert lan == {"TCPIP::192.168.1.10"}
    # a host name and its address are one instrument (a reviewer at stop 39: two locks)
    assert canonical("TCPIP0::localhost::INSTR") == canonical("TCPIP::127.0.0.1::inst0::INSTR")
    assert canonical("TCPIP0::no-such-host.invalid::INSTR") == "TCPIP::NO-SUCH-HOST.INVALID"
    assert canonical("USB0::0x0957::0x2C07::MY1::INSTR") == canonical("USB::2391::11271::my1")
    with pytest.raises(InstrumentInUse, match="the vibrometer and the stage are one device"):
        lock_instruments({"vibrometer": "ASRL3::INSTR", "stage": "COM3"})
    assert _locks(tmp_path) == []  # nothing kept


def test_a_host_name_that_does_not_resolve_in_time_is_its_own_key(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A reviewer: the lookup had no time limit and ran while the process's lock guard was
    held, so a name server that did not answer held every other lock of the process too."""
    import socket
    import threading
    import time

    import daq.instrument_lock as il

    release = threading.Event()

    def hangs(*args: object, **kwargs: object) -> list[object]:
        release.wait(10)
        return []

    monkeypatch.setattr(socket, "getaddrinfo", hangs)
    monkeypatch.setattr(il, "LOOKUP_TIMEOUT_S", 0.2)
    t0 = time.monotonic()
    try:
        assert il.canonical("TCPIP0::slow-dns.lab::INSTR") == "TCPIP::SLOW-DNS.LAB"
        assert time.monotonic() - t0 < 2.0
    finally:
        release.set()
