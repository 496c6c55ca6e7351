"""``biafc study --scheduler``: an address where no Dask scheduler answers is refused in one
line, exit 2, before the output is made; a cluster without workers is said, not waited on in
silence. Before: 30 s then exit 1 with a 'failed' output made; a port where another service
answers (the scheduler's dashboard) hung for ever, or ended in a MemoryError; no worker, or the
last one killed, was an endless wait without a word."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from daq.cli.biafc import main
from daq.study_runner import SchedulerUnreachable, connect_scheduler, no_worker_notice

from .conftest import TINY


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_nothing_listening_is_refused_at_once_and_no_output_is_made(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study = tmp_path / "s.yaml"
    study.write_text(TINY)
    out = tmp_path / "s.h5"
    address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.monotonic()
    assert main(["study", str(study), "--scheduler", address, "--out", str(out), "-q"]) == 2
    assert time.monotonic() - t0 < 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and address in err[0] and "nothing answers there" in err[0], err
    assert not out.exists()


def test_another_service_on_the_port_is_refused_not_waited_on() -> None:
    """An HTTP server that answers and keeps the line open, like a dashboard."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    conns: list[socket.socket] = []

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conns.append(conn)
            conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\n\r\n<html>")

    threading.Thread(target=serve, daemon=True).start()
    t0 = time.monotonic()
    try:
        with pytest.raises(SchedulerUnreachable, match="no Dask scheduler"):
            connect_scheduler(f"tcp://127.0.0.1:{server.getsockname()[1]}", timeout_s=2.0)
    finally:
        server.close()
        for conn in conns:
            conn.close()
    assert time.monotonic() - t0 < 10


def test_a_cluster_without_workers_is_said_once() -> None:
    class Scheduler:
        address = "tcp://10.0.0.9:8786"

    class Client:
        scheduler = Scheduler()

        def __init__(self) -> None:
            self.workers: dict[str, Any] = {}

        def scheduler_info(self) -> dict[str, Any]:
            return {"workers": self.workers}

    notes: list[str] = []
    client = Client()
    with no_worker_notice(client, notes.append, after_s=1.5):
        time.sleep(4.0)
    assert len(notes) == 1 and "no worker connected to tcp://10.0.0.9:8786" in notes[0]
    assert "dask worker tcp://10.0.0.9:8786" in notes[0]
    client.workers = {"w": {}}
    with no_worker_notice(client, notes.append, after_s=1.5):
        time.sleep(3.0)
    assert len(notes) == 1  # workers there: nothing said
