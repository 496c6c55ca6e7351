"""A process that left a file open ends through :func:`protocols.left_open.exit_leaving_them`:
its own status, its log files flushed, Python's exit handlers run (the stability verdicts are
written to the cache there). HDF5's clean-up, which is the C library's, is skipped: the bench
window's test on a real full disk (tests/gui/test_gui_exit.py) shows it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from protocols import left_open

ROOT = Path(__file__).resolve().parents[2]

_SCRIPT = """
import atexit, logging, sys
from protocols.left_open import exit_leaving_them, files_left_open, leave_open
logging.basicConfig(filename=sys.argv[1], level=logging.INFO)
logging.getLogger("biafc.run").info("the last line of the run")
atexit.register(print, "exit handler ran", end=" ")  # the stability verdicts' flush, say
leave_open("a.h5"); leave_open("a.h5"); leave_open("b.h5")
print(",".join(files_left_open()), end=" ")
exit_leaving_them(5)
"""


def test_the_exit_keeps_the_status_flushes_the_log_and_runs_the_exit_handlers(
    tmp_path: Path,
) -> None:
    log = tmp_path / "RUN.log"
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(log)], capture_output=True,
                          text=True, cwd=ROOT, timeout=60)  # fmt: skip
    assert done.returncode == 5, done.stderr
    assert done.stdout == "a.h5,b.h5 exit handler ran "  # flushed, each file once
    assert "the last line of the run" in log.read_text()


def test_each_test_starts_with_no_file_left_open() -> None:
    assert left_open.files_left_open() == ()
