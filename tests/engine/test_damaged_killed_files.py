"""A run file left by a killed writer AND damaged (bytes overwritten in its metadata, or cut
short): ``biafc figures``, ``biafc repair`` and ``--resume`` refuse it at once in one line
(exit 2), where HDF5's SWMR reader used to retry the failing metadata read with a doubling
back-off for ever (:mod:`protocols.swmr_read`); the undamaged killed file still reads, and
is not changed by reading it."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from protocols.recover import has_consistency_flags
from protocols.runfile import read_run
from protocols.swmr_read import open_swmr, retry_bound_available

from .helpers import PROTOCOL, killed_run
from .test_cli import _spawn, _wait_done

ROOT = Path(__file__).resolve().parents[2]
#: a hang fails the test instead of blocking CI; the refusals take about 1 s
LIMIT_S = 30.0


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The bytes of a run file whose writer was SIGKILLed after 2 points."""
    path = killed_run(tmp_path_factory.mktemp("killed"), 2)
    assert has_consistency_flags(path)  # the killed writer's SWMR flags are set
    return path.read_bytes()


def _overwrite(at: int, n: int, byte: bytes) -> Callable[[bytes], bytes]:
    def damage(data: bytes) -> bytes:
        b = bytearray(data)
        b[at : at + n] = byte * n
        return bytes(b)

    return damage


def _object_header(which: int) -> Callable[[bytes], bytes]:
    """Overwrite 16 bytes inside an object header (signature ``OHDR``): the first, a middle
    one or the last."""

    def damage(data: bytes) -> bytes:
        at = [i for i in range(len(data)) if data.startswith(b"OHDR", i)]
        assert len(at) >= 3
        pos = at[{0: 0, 1: len(at) // 2, 2: -1}[which]]
        return _overwrite(pos + 8, 16, b"\xff")(data)

    return damage


DAMAGES: dict[str, Callable[[bytes], bytes]] = {
    # superblock v3: end-of-file address at 28, root object header address at 36
    "superblock_eof_zeroed": _overwrite(28, 4, b"\0"),
    "superblock_root_zeroed": _overwrite(36, 4, b"\0"),
    "bytes_100_600_zeroed": _overwrite(100, 500, b"\0"),
    "first_object_header": _object_header(0),
    "middle_object_header": _object_header(1),
    "last_object_header": _object_header(2),
    "cut_to_4096": lambda data: data[:4096],
    "cut_by_100": lambda data: data[:-100],
}


def _command(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """A console script run as its own process (``code`` calls its entry point)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=LIMIT_S,
        env=env,
    )


def _biafc(*args: str) -> subprocess.CompletedProcess[str]:
    return _command(
        "import sys; from daq.cli.biafc import main; sys.exit(main(sys.argv[1:]))", *args
    )


def _run_protocol(*args: str) -> subprocess.CompletedProcess[str]:
    return _command(
        "import sys; from daq.cli.entry import run_protocol; sys.exit(run_protocol())", *args
    )


@pytest.mark.parametrize("name", list(DAMAGES))
def test_figures_refuse_a_damaged_killed_file_at_once_in_one_line(
    killed: bytes, tmp_path: Path, name: str
) -> None:
    path = tmp_path / f"{name}.h5"
    path.write_bytes(DAMAGES[name](killed))
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    res = _biafc("figures", str(path), "--out", str(tmp_path / "figs"))  # hung before
    assert res.returncode == 2, res.stdout + res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0], res.stderr
    assert "damaged" in lines[0] or "truncated" in lines[0], lines[0]
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
    assert not (tmp_path / "figs").exists()


@pytest.mark.parametrize("name", ["bytes_100_600_zeroed", "middle_object_header"])
def test_repair_and_resume_refuse_a_damaged_killed_file_in_one_line(
    killed: bytes, tmp_path: Path, name: str
) -> None:
    path = tmp_path / f"{name}.h5"
    path.write_bytes(DAMAGES[name](killed))
    for res in (_biafc("repair", str(path)), _run_protocol("--resume", str(path))):
        assert res.returncode == 2, res.stdout + res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0], res.stderr


def test_the_undamaged_killed_file_reads_through_the_bounded_retry_unchanged(
    killed: bytes, tmp_path: Path
) -> None:
    assert retry_bound_available()  # else open_swmr falls back to HDF5's unbounded retry
    path = tmp_path / "k.h5"
    path.write_bytes(killed)
    with open_swmr(path) as f:
        assert f.swmr_mode and f.attrs["status"] == "running"
    run = read_run(path)
    assert sum(int((s.done == 1).sum()) for s in run.scans.values()) >= 2
    assert path.read_bytes() == killed


def test_a_live_run_reads_through_the_bounded_retry_while_its_writer_flushes(
    tmp_path: Path,
) -> None:
    """The bound leaves a live writer's flush time to finish (a reader following a run): every
    read while points are flushed succeeds, and sees no fewer points than the one before."""
    proto = tmp_path / "proto.yaml"
    proto.write_text(PROTOCOL)
    path = tmp_path / "live.h5"
    proc = _spawn([str(proto), "--out", str(path), "--seed", "5"], read_s=0.01)
    reads, last = 0, 0
    try:
        _wait_done(path, 1, proc)
        while proc.poll() is None:
            run = read_run(path)
            done = sum(int((s.done == 1).sum()) for s in run.scans.values())
            assert done >= last
            reads, last = reads + 1, done
            if done == sum(s.done.size for s in run.scans.values()):
                break  # the writer closes the file next (outside SWMR): not this test's case
        assert proc.wait(60) == 0
    finally:
        proc.kill()
        proc.wait(10)
    assert reads >= 5, reads
