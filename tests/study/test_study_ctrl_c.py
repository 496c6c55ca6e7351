"""A terminal's Ctrl-C during a study on its LocalCluster: SIGINT reaches every process of the
terminal's group, the workers' too. Before, each worker printed its own KeyboardInterrupt
traceback (4 tracebacks, 72 lines) before the study's line; now the workers ignore SIGINT
(:mod:`daq.study_worker`), the study ends the cluster itself, and says how to continue."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import TINY

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(sys.platform == "win32", reason="process groups and SIGINT are POSIX")
def test_ctrl_c_in_the_terminal_is_one_line_not_the_workers_tracebacks(tmp_path: Path) -> None:
    study = tmp_path / "s.yaml"
    study.write_text(
        TINY.replace("duration: 2 ms", "duration: 100 ms").replace("count: 3}", "count: 12}")
    )
    log = tmp_path / "out.txt"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-c", "import sys; from daq.cli.biafc import main; sys.exit(main())"]
    with log.open("w") as out:
        proc = subprocess.Popen(
            [*cmd, "study", str(study), "--workers", "2", "--out", str(tmp_path / "s.h5")],
            cwd=tmp_path,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # a group of its own, as a terminal's job is
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        deadline = time.monotonic() + 120
        while "cell " not in log.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log.read_text()
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the whole group
        rc = proc.wait(60)
    text = log.read_text()
    assert rc == 130, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    assert "run again to continue" in text and text.rstrip().endswith("biafc study: interrupted")


def test_distributeds_own_ctrl_c_error_is_not_printed() -> None:
    """CI once printed tornado's 12-line traceback of distributed's own NameError ("cannot
    access free variable 'future'", in the cancel callback of distributed.utils.sync) when a
    Ctrl-C interrupted a blocking call, before the study's clean last line. Only that record
    is dropped."""
    import logging
    import sys

    from daq.study_runner import _drop_sync_cancel_error

    def record_of(filename: str, name: str) -> logging.LogRecord:
        space: dict[str, object] = {}
        src = (
            f"def {name}():\n"
            "    raise NameError(\"cannot access free variable 'future' where it is not "
            'associated with a value in enclosing scope")\n'
        )
        exec(compile(src, filename, "exec"), space)
        try:
            space[name]()  # type: ignore[operator]
        except NameError:
            info = sys.exc_info()
        return logging.LogRecord("tornado.application", logging.ERROR, filename, 1,
                                 "Exception in callback", None, info)  # fmt: skip

    assert not _drop_sync_cancel_error(record_of("/x/distributed/utils.py", "cancel"))
    assert _drop_sync_cancel_error(record_of("/x/daq/mine.py", "cancel"))
    assert _drop_sync_cancel_error(record_of("/x/distributed/utils.py", "other"))
    plain = logging.LogRecord("tornado.application", logging.ERROR, "f", 1, "m", None, None)
    assert _drop_sync_cancel_error(plain)
