"""A study stopped by SIGTERM (``kill``, a batch system's time limit) or SIGHUP (the terminal or
the ssh session closed). Before, the signal's default action ended the process where it stood:
exit 143 without a word, and the output left open for writing, which plain h5py (and any reader
but ``biafc figures``) refused until ``biafc repair``. Now such a signal takes Ctrl-C's path:
the output is closed with what finished, the line says how to continue, and the exit status is
128 + the signal's number."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from .conftest import TINY

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(sys.platform == "win32", reason="SIGTERM and SIGHUP as POSIX sends them")
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_a_stop_signal_closes_the_study_output_as_ctrl_c_does(tmp_path: Path, sig: str) -> None:
    signum = int(getattr(signal, sig))
    study = tmp_path / "s.yaml"
    study.write_text(
        TINY.replace("duration: 2 ms", "duration: 20 ms").replace("count: 3}", "count: 40}")
    )
    out = tmp_path / "s.h5"
    log = tmp_path / "out.txt"
    cmd = [sys.executable, "-c", "import sys; from daq.cli.biafc import main; sys.exit(main())"]
    with log.open("w") as text_out:
        proc = subprocess.Popen(
            [*cmd, "study", str(study), "--workers", "0", "--out", str(out)],
            cwd=tmp_path,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
            stdout=text_out,
            stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + 120
        while "cell " not in log.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log.read_text()
            time.sleep(0.2)
        proc.send_signal(signum)
        rc = proc.wait(60)
    text = log.read_text()
    assert rc == 128 + signum, text
    with h5py.File(out, "r") as f:  # refused before ("file is already open for write")
        assert f.attrs["status"] == "incomplete"
        assert 0 < int((f["cells/status"][...] != 0).sum()) < 80
    if sig == "SIGTERM":  # SIGHUP: the terminal is gone, the lines go nowhere
        assert "Traceback" not in text, text
        assert "run again to continue" in text
        assert text.rstrip().endswith("biafc study: interrupted by SIGTERM"), text
