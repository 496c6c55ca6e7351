"""A run file in a folder this user cannot write (an archive, a colleague's folder): its lock
cannot be written beside it. ``biafc repair`` (and ``biafc study``, ``--resume``) ended in a
``PermissionError`` traceback from the lock; now they are refused in one line naming the
folder (:class:`daq.store.lock.LockNotWritable`, exit 2)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from daq.store.lock import FileInUse, LockNotWritable, RunFileLock

ROOT = Path(__file__).resolve().parents[2]


def test_a_lock_that_cannot_be_written_is_refused_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_open = os.open

    def refused(path: object, *args: object, **kw: object) -> int:
        if str(path).endswith(".tmp"):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "open", refused)
    with pytest.raises(LockNotWritable) as err:
        RunFileLock(tmp_path / "run.h5").acquire()
    msg = str(err.value)
    assert isinstance(err.value, FileInUse)  # every writer already refuses that in one line
    assert "\n" not in msg and "Permission denied" in msg and str(tmp_path) in msg
    assert "run.h5.lock" in msg


@pytest.mark.skipif(
    sys.platform != "linux" or os.geteuid() != 0 or shutil.which("setpriv") is None,
    reason="runs the command as another user: needs Linux, root and setpriv",
)
def test_biafc_repair_in_a_read_only_folder_says_so_in_one_line() -> None:
    import tempfile

    import numpy as np

    from protocols.runfile import RunFileWriter, ScanSpec

    from .helpers import chain_info

    top = Path(tempfile.mkdtemp(prefix="biafc-ro-"))  # pytest's own folders are 0700
    try:
        folder = top / "archive"
        folder.mkdir()
        path = folder / "run.h5"
        spec = ScanSpec("ltr", np.array([1e-6]), "m", np.arange(31, 32, dtype=np.int32),
                        np.arange(100) / 1e5, 8920.0, cycles=21.0, drive_units="m")  # fmt: skip
        w = RunFileWriter.create(path, backend="sim", chain=chain_info(), scans=[spec])
        w.close("aborted")
        home = top / "home"
        home.mkdir()
        for p, mode in ((top, 0o755), (folder, 0o755), (path, 0o644), (home, 0o777)):
            os.chmod(p, mode)  # the archive readable by all, writable by its owner (root) only
        env = dict(os.environ, PYTHONPATH=str(ROOT), HOME=str(home), BIAFC_CACHE_DIR=str(home))
        cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable,
               "-c", "from daq.cli.biafc import main; raise SystemExit(main())", "repair",
               str(path)]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120, cwd=ROOT)
    finally:
        shutil.rmtree(top, ignore_errors=True)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert "cannot write its lock run.h5.lock" in lines[0] and str(folder) in lines[0]
