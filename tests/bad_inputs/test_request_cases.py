"""Issue 16: every bad request refused up front by the one validation layer (daq/request.py).

Each case goes through the real entry point (``run_protocol``'s ``main``) with
``daq.connect.connect_bench`` replaced by a stand-in that fails the test if called, and must end
in exit status 2 with exactly one line on stderr, no traceback, nothing written (the scratch
folder is unchanged: no run file, no RUN.log, no lock, no folder) and within 2 s.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

import daq.connect
from daq.cli import run_protocol as rp
from protocols.bench import default_bench_path, load_bench
from protocols.runfile import ChainInfo, ScanSpec
from tests.bad_inputs.runner import tree
from tests.engine.helpers import PROTOCOL

#: every refusal within this wall time (s)
MAX_SECONDS = 2.0


@pytest.fixture
def refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> Callable[[list[str]], str]:
    """``refused(argv)`` runs ``run_protocol argv`` in ``tmp_path`` and returns its one line
    after checking exit 2, one line, no traceback, no instrument, nothing written, < 2 s."""

    def forbidden(*a: object, **k: object) -> None:
        raise AssertionError("an instrument was opened (connect_bench called)")

    monkeypatch.setattr(daq.connect, "connect_bench", forbidden)
    monkeypatch.chdir(tmp_path)

    def run(argv: list[str]) -> str:
        before = tree(tmp_path)
        capsys.readouterr()
        t0 = time.monotonic()
        code = rp.main(argv)
        seconds = time.monotonic() - t0
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert "Traceback" not in captured.err + captured.out
        assert code == 2, f"exit {code}: {err}"
        assert len(err.splitlines()) == 1, err
        assert err.startswith("run_protocol: error: "), err
        assert tree(tmp_path) == before, "something was written"
        assert seconds < MAX_SECONDS, f"{seconds:.2f} s"
        return err.removeprefix("run_protocol: error: ")

    return run


def _protocol(tmp_path: Path, text: str = PROTOCOL, name: str = "proto.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _bench(tmp_path: Path, old: str, new: str, name: str = "bench.yaml") -> Path:
    text = default_bench_path().read_text()
    assert old in text, old
    p = tmp_path / name
    p.write_text(text.replace(old, new))
    return p


def _run_file(tmp_path: Path, protocol_text: str = PROTOCOL, status: str = "aborted") -> Path:
    """A run file of ``protocol_text`` on the shipped bench, left ``status`` with no point
    measured: made by the store itself, no instrument involved."""
    from daq.engine import make_plan
    from daq.store import create_run
    from protocols.schema import parse_protocol

    pf = parse_protocol(protocol_text, "proto.yaml")
    bf = load_bench()
    plan = make_plan(pf, bf)
    acq = pf.protocol.acquisition
    time_s = (np.arange(acq.n_samples()) - acq.n_pretrigger) / acq.rate
    scans = [
        ScanSpec(
            direction=d,
            amplitudes=plan.amplitudes,
            amplitude_units=plan.amplitude_units,
            cylinders=plan.cylinders,
            time_s=time_s,
            f_center_Hz=float(pf.protocol.burst[d].f_center),  # type: ignore[index]
            cycles=5.0,
            averages=pf.protocol.averages,
        )
        for d in plan.directions
    ]
    n = 31
    chain = ChainInfo(np.full(n, 0.1), 0.0136, 5.0, 1e9, np.ones((n, 2)), 2 * np.ones((n, 2)))
    path = tmp_path / "run.h5"
    writer = create_run(
        path,
        backend="sim",
        chain=chain,
        scans=scans,
        protocol_yaml=protocol_text,
        bench_yaml=bf.text,
        snapshot={},
        seed=0,
    )
    writer.close(status)  # type: ignore[arg-type]
    return path


# -- the resume file, checked before anything is connected -----------------------------------
def test_resume_with_another_protocols_file(tmp_path: Path, refused) -> None:
    run = _run_file(tmp_path)
    other = _protocol(tmp_path, PROTOCOL.replace("name: fake_scan", "name: other_scan"), "o.yaml")
    line = refused([str(other), "--resume", str(run)])
    assert "another protocol" in line and "'fake_scan', not 'other_scan'" in line


def test_resume_with_a_modified_protocol_names_the_change(tmp_path: Path, refused) -> None:
    run = _run_file(tmp_path)
    changed = _protocol(tmp_path, PROTOCOL.replace("averages: 2", "averages: 3"), "c.yaml")
    line = refused([str(changed), "--resume", str(run)])
    assert "another protocol" in line and "averages: 2 in the file, 3 now" in line


def test_resume_of_a_complete_file_with_its_protocol(tmp_path: Path, refused) -> None:
    run = _run_file(tmp_path, status="complete")
    bench = str(default_bench_path())
    line = refused([str(_protocol(tmp_path)), "--bench", bench, "--resume", str(run)])
    assert "complete already" in line and "--out" in line


def test_resume_of_an_hdf5_file_that_is_no_run(tmp_path: Path, refused) -> None:
    bogus = tmp_path / "bogus.h5"
    with h5py.File(bogus, "w") as f:
        f["x"] = np.arange(3)
    bench = str(default_bench_path())
    line = refused([str(_protocol(tmp_path)), "--bench", bench, "--resume", str(bogus)])
    assert line.startswith("--resume:") and "not a biafc run file" in line


def test_resume_of_a_text_file(tmp_path: Path, refused) -> None:
    text = tmp_path / "notes.h5"
    text.write_text("not a run file\n")
    bench = str(default_bench_path())
    line = refused([str(_protocol(tmp_path)), "--bench", bench, "--resume", str(text)])
    assert line.startswith("--resume:") and str(text) in line


def test_resume_on_another_bench_lists_the_differences(tmp_path: Path, refused) -> None:
    run = _run_file(tmp_path)
    other = _bench(tmp_path, "gain: 20 ", "gain: 40 ")
    line = refused([str(_protocol(tmp_path)), "--bench", str(other), "--resume", str(run)])
    assert "another bench" in line and "amplifier.gain: 20" in line and "40 now" in line
    assert "--accept-bench-change" in line


def test_resume_of_a_file_another_process_writes(tmp_path: Path, refused) -> None:
    from daq.store.lock import lock_path

    run = _run_file(tmp_path)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        lock_path(run).write_text(json.dumps({"host": socket.gethostname(), "pid": other.pid}))
        line = refused([str(_protocol(tmp_path)), "--resume", str(run)])
        assert f"process {other.pid}" in line
    finally:
        other.kill()
        other.wait()


def test_resume_alone_of_a_file_another_process_writes(tmp_path: Path, refused) -> None:
    from daq.store.lock import lock_path

    run = _run_file(tmp_path)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        lock_path(run).write_text(json.dumps({"host": socket.gethostname(), "pid": other.pid}))
        assert f"process {other.pid}" in refused(["--resume", str(run), "--dry-run"])
    finally:
        other.kill()
        other.wait()


def test_dry_run_of_a_refused_resume_is_refused_too(tmp_path: Path, refused) -> None:
    run = _run_file(tmp_path)
    changed = _protocol(tmp_path, PROTOCOL.replace("averages: 2", "averages: 3"), "c.yaml")
    assert "another protocol" in refused([str(changed), "--resume", str(run), "--dry-run"])


# -- the output ------------------------------------------------------------------------------
@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_out_in_proc_is_refused_up_front(tmp_path: Path, refused) -> None:
    line = refused([str(_protocol(tmp_path)), "--out", "/proc/x.h5"])
    assert line.startswith("--out: cannot write /proc/x.h5: nothing can be created in /proc")
    assert not Path("/proc/x.h5").exists()


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_out_under_proc_in_a_new_folder_is_refused(tmp_path: Path, refused) -> None:
    line = refused([str(_protocol(tmp_path)), "--out", "/proc/runs/x.h5"])
    assert line.startswith("--out: cannot write /proc/runs/x.h5: nothing can be created in /proc")


# -- Ctrl-C before the program has started -------------------------------------------------
def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )


def test_ctrl_c_while_the_program_is_still_importing_is_one_line_and_130() -> None:
    """The console script imports daq.cli.entry first: a SIGINT while the rest is imported
    (before run_protocol.main installs its handling) is one line and exit 130."""
    proc = _python(
        "import os, signal, time\n"
        "import daq.cli.entry\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(10)\n"
    )
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (
        "run_protocol: interrupted by SIGINT before the run started: nothing was switched on, "
        "no file written"
    )


def test_ctrl_c_after_the_run_ended_keeps_its_exit_status() -> None:
    proc = _python(
        "import os, signal, sys, time\n"
        "import daq.cli.entry as entry, daq.cli.run_protocol as rp\n"
        "rp.main = lambda: 0\n"
        "code = entry.run_protocol()\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(0.2)\n"
        "sys.exit(code)\n"
    )
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr


def test_the_run_protocol_console_script_goes_through_the_quiet_entry() -> None:
    import tomllib

    root = Path(__file__).resolve().parents[2]
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["run_protocol"] == "daq.cli.entry:run_protocol"
