"""The lab bench file's whole path to connected drivers on the real libraries: the template's
resources pointed at the project's emulators behind a TCP socket (the generator, as a VISA
``TCPIP::...::SOCKET`` resource on pyvisa-py) and two pseudo terminals (the vibrometer as a VISA
``ASRL`` resource on pyvisa-py, the stage as a port on pyserial), the DAQ card on the stand-in
``nidaqmx``. CI otherwise never runs a driver over pyvisa-py or pyserial: the simulated bench
uses in-process transports. ``biafc check`` must find every instrument as the file says."""

from __future__ import annotations

import os
import socket
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from instruments.clock import SystemClock
from protocols.bench import default_bench_path
from sim_backend.emulators import KeysightEmulator, PolytecEmulator, ZaberEmulator

from .pty_line import serve_lines
from .standin_nidaqmx import Card, install

pytestmark = pytest.mark.skipif(
    sys.platform == "win32" or not hasattr(os, "openpty"), reason="needs pseudo terminals"
)


def _answer(emulator: Any, end: bytes) -> Callable[[bytes], bytes | None]:
    """The emulator's reply lines to a line, each ended by ``end``."""

    def answer(line: bytes) -> bytes | None:
        reply = emulator.handle(line)
        return (
            None
            if reply is None
            else b"".join(out.encode("latin-1") + end for out in reply.split("\n"))
        )

    return answer


def _serve_socket(server: socket.socket, emulator: Any, stop: threading.Event) -> None:
    server.settimeout(0.1)
    while not stop.is_set():
        try:
            conn, _ = server.accept()
        except TimeoutError:
            continue
        conn.settimeout(0.1)
        buf = b""
        with conn:
            while not stop.is_set():
                try:
                    data = conn.recv(65536)
                except TimeoutError:
                    continue
                if not data:
                    break
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    reply = emulator.handle(line)
                    if reply is not None:
                        conn.sendall(reply.encode() + b"\n")


@pytest.fixture
def rig(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """The template bench file with its resources on the emulators; the path to it."""
    pytest.importorskip("pyvisa_py")
    import tty

    stop = threading.Event()
    threads: list[threading.Thread] = []
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    threads.append(threading.Thread(target=_serve_socket, args=(server, KeysightEmulator(), stop)))
    ports, fds = [], []
    vibrometer = PolytecEmulator(range_name="VD-09 50mm/s/V")  # echo on: the strict case
    for emulator, end in ((vibrometer, b"\n"), (ZaberEmulator(SystemClock()), b"\r\n")):
        far, near = os.openpty()
        tty.setraw(near)
        fds += [far, near]
        ports.append(os.ttyname(near))
        threads.append(
            threading.Thread(target=serve_lines, args=(far, _answer(emulator, end), stop))
        )
    for t in threads:
        t.daemon = True
        t.start()
    text = default_bench_path().with_name("lab_bench.yaml").read_text()
    text = text.replace(
        "TCPIP0::192.168.1.10::INSTR", f"TCPIP0::127.0.0.1::{server.getsockname()[1]}::SOCKET"
    )
    text = text.replace("ASRL3::INSTR", f"ASRL{ports[0]}::INSTR").replace("ASRL4::INSTR", ports[1])
    # the template as shipped, max_rate included: the stand-in is a PCIe-6361 (2 channels)
    bench = tmp_path / "bench.yaml"
    bench.write_text(text)
    install(monkeypatch, Card())
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path / "cache"))  # the instrument locks
    try:
        yield bench
    finally:
        stop.set()
        for t in threads:
            t.join(2)
        server.close()
        for fd in fds:
            os.close(fd)


def test_biafc_check_finds_the_lab_bench_over_pyvisa_py_and_pyserial(
    rig: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from daq.cli.biafc import main

    assert main(["check", str(rig)]) == 0, capsys.readouterr()
    out = capsys.readouterr().out
    assert "every instrument matches the bench file" in out
    for seen in ("Keysight Technologies", "OFV-5000 / OFV-534", "VD-09 50mm/s/V", "device id"):
        assert seen in out, seen
