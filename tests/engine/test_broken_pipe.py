"""``biafc bands | head -1``: a reader that stops early is not a failure. Before, the command
ended in a BrokenPipeError traceback and exit 1."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_closed_pipe_ends_the_command_quietly() -> None:
    code = "import sys; from daq.cli.shutdown import biafc; sys.exit(biafc())"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "bands"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # as head does after its line
    err = proc.stderr.read().decode()
    assert proc.wait(60) == 0, err
    assert first.startswith(b"# chain:") and "Traceback" not in err, err
