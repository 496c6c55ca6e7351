"""Every command that writes checks where, before its work (:mod:`daq.store.writable`):
``biafc simulate`` ran its model for 20 s and then failed to create its file, and
``biafc figures`` beside a run file in a read-only folder ended in a ``PermissionError``
traceback. Now each is refused up front, in one line, exit 2."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from daq.store.writable import cannot_write

ROOT = Path(__file__).resolve().parents[2]


def test_the_nearest_existing_folder_is_what_is_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert cannot_write(tmp_path / "new" / "deeper" / "figs", "--out") is None
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    assert cannot_write(a_file / "figs", "--out") == (
        f"--out: cannot write {a_file / 'figs'}: {a_file} is a file, not a folder"
    )
    monkeypatch.setattr(os, "access", lambda *a, **k: False)
    assert cannot_write(tmp_path / "figs", "--figures") == (
        f"--figures: cannot write in {tmp_path} (permission denied)"
    )


#: the commands that write, each run where this user cannot write (the current folder)
COMMANDS = [
    ["figures", "run.h5"],
    ["figures", "--alpha-sweep"],
    ["simulate", "--direction", "ltr", "--amplitude", "1um", "--out", "sim.h5"],
    ["regime", "--out", "reg", "--count", "3"],
    ["compare", "run.h5"],
    ["calibrate", "run.h5"],
    ["accuracy", "--quick", "--plot", "work.png"],
    ["bands", "--csv", "bands.csv"],
]


@pytest.fixture(scope="module")
def read_only_folder() -> object:
    """A folder with a run file, readable by everyone and writable by root only, and a home
    folder for the other user."""
    if sys.platform != "linux" or os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("runs the commands as another user: needs Linux, root and setpriv")
    from daq.cli.biafc import main

    top = Path(tempfile.mkdtemp(prefix="biafc-ro-"))  # pytest's own folders are 0700
    folder, home = top / "archive", top / "home"
    folder.mkdir()
    home.mkdir()
    assert main(["simulate", "--direction", "ltr", "--amplitude", "2um", "--duration", "3ms",
                 "--out", str(folder / "run.h5")]) == 0  # fmt: skip
    for p, mode in ((top, 0o755), (folder, 0o755), (folder / "run.h5", 0o644), (home, 0o777)):
        os.chmod(p, mode)
    yield folder, home
    shutil.rmtree(top, ignore_errors=True)


@pytest.mark.parametrize("args", COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_a_command_is_refused_before_its_work_where_it_cannot_write(
    read_only_folder: tuple[Path, Path], args: list[str]
) -> None:
    folder, home = read_only_folder
    env = dict(os.environ, PYTHONPATH=str(ROOT), HOME=str(home), BIAFC_CACHE_DIR=str(home))
    cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable,
           "-c", "import sys; from daq.cli.biafc import main; sys.exit(main())", *args]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300, cwd=folder)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert lines[-1].endswith("cannot write in . (permission denied)"), lines
    assert sorted(p.name for p in folder.iterdir()) == ["run.h5"]  # nothing written there


def test_simulate_makes_the_folder_its_file_goes_into(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The check accepts a folder that does not exist yet; ``biafc simulate`` then ran its model
    and failed in HDF5's own words (errno = 2, o_flags = 242). It makes the folder, as
    ``run_protocol`` does."""
    from daq.cli.biafc import main

    out = tmp_path / "new" / "deeper" / "s.h5"
    args = ["simulate", "--direction", "ltr", "--amplitude", "1um", "--duration", "5ms"]
    assert main([*args, "--rate", "200kS/s", "--out", str(out)]) == 0, capsys.readouterr().err
    assert out.exists()


def test_bands_csv_makes_its_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``biafc bands --csv new/b.csv`` printed the table, then refused (the folder did not
    exist, though the check had allowed it)."""
    from daq.cli.biafc import main

    out = tmp_path / "new" / "b.csv"
    assert main(["bands", "--csv", str(out)]) == 0
    assert out.read_text().startswith("cylinder")
