"""Files left by a killed writer (issue 15): ``biafc repair`` and ``--resume`` make them readable
by plain h5py without losing a point; readers (``read_run``, ``biafc figures``) open them
without changing a byte; a kill while creating leaves nothing under the run's name."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np

import daq.connect
from daq.cli import run_protocol as rp
from daq.cli.biafc import main as biafc
from daq.store.lock import lock_path
from protocols.runfile import PointState, read_run

from .fakes import FakeWorld, fake_bench
from .test_cli import _spawn, _wait_done

ROOT = Path(__file__).resolve().parents[2]


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _plain_h5py_opens(p: Path) -> bool:
    try:
        with h5py.File(p, "r") as f:
            return f.attrs["format"] == "biafc-run"
    except OSError:
        return False


def _killed_run(proto_file: Path, path: Path) -> int:
    proc = _spawn([str(proto_file), "--out", str(path), "--seed", "5"])
    _wait_done(path, 2, proc)
    proc.kill()
    proc.wait(10)
    return proc.pid


def _done(p: Path) -> dict[str, np.ndarray]:
    return {d: s.done.copy() for d, s in read_run(p).scans.items()}


def test_repair_makes_a_killed_file_readable_by_plain_h5py_without_losing_a_point(
    proto_file, tmp_path, capsys
) -> None:
    killed = tmp_path / "killed.h5"
    pid = _killed_run(proto_file, killed)
    assert not _plain_h5py_opens(killed)  # "file is already open for write"
    assert lock_path(killed).exists()  # the dead writer's lock
    before = _digest(killed)
    done = _done(killed)  # a reader sees every point ...
    assert _digest(killed) == before  # ... without changing the file
    assert biafc(["repair", str(killed)]) == 0
    line = capsys.readouterr().out
    assert "cleared the open-for-write flags" in line and "aborted" in line
    assert f"process {pid}" in line  # the stale lock was named and taken over
    assert _plain_h5py_opens(killed)
    after = _done(killed)
    for d in done:
        np.testing.assert_array_equal(done[d], after[d])
    run = read_run(killed)
    assert run.status == "aborted" and any("repaired" in m for _, _, m in run.log)
    assert any("did not close the file (it was killed, or its disk" in m for _, _, m in run.log)
    # a repair measures nothing: it stamps its own time, not 'resumed' or 'finished'
    assert "repaired" in run.attrs and "resumed" not in run.attrs
    assert "finished" not in run.attrs
    assert not lock_path(killed).exists()
    assert biafc(["repair", str(killed)]) == 0  # idempotent
    assert "nothing to repair" in capsys.readouterr().out


def test_resume_of_a_killed_file_leaves_it_readable_by_plain_h5py(
    proto_file, tmp_path, monkeypatch
) -> None:
    killed = tmp_path / "k.h5"
    _killed_run(proto_file, killed)
    monkeypatch.setattr(
        daq.connect, "connect_bench", lambda bf, seed=None, **k: fake_bench(FakeWorld(seed=seed))
    )
    assert rp.main([str(proto_file), "--resume", str(killed), "--quiet"]) == 0
    assert _plain_h5py_opens(killed)
    assert all(np.all(d == PointState.DONE) for d in _done(killed).values())


def test_figures_read_a_killed_file_without_changing_it(proto_file, tmp_path, capsys) -> None:
    killed = tmp_path / "f.h5"
    _killed_run(proto_file, killed)
    assert biafc(["repair", str(killed)]) == 0
    # then killed again while a writer held it open without SWMR (as when closing)
    code = f"import os, h5py; f = h5py.File({str(killed)!r}, 'r+'); os._exit(9)"
    assert _python(code, tmp_path) == 9
    assert not _plain_h5py_opens(killed)
    capsys.readouterr()
    before = _digest(killed)
    assert biafc(["figures", str(killed), "--out", str(tmp_path / "figs")]) == 0
    assert "written" in capsys.readouterr().out
    assert _digest(killed) == before


def _python(code: str, cwd: Path) -> int:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, env=env
    ).returncode


def test_a_kill_while_closing_leaves_a_file_readers_and_repair_open(tmp_path) -> None:
    """The closing writer re-opens the file without SWMR to set the status: killed there."""
    path = tmp_path / "closing.h5"
    rc = _python(
        f"""
        import os, h5py, numpy as np
        from protocols.runfile import RunFileWriter, ScanSpec, ChainInfo
        chain = ChainInfo(np.ones(3), 0.01, 5.0, 1e9, np.ones((3, 1)), np.ones((3, 1)))
        spec = ScanSpec("ltr", np.array([1.0]), "V", np.array([1, 2], np.int32),
                        np.linspace(0, 1e-3, 8), 8e3, cycles=5)
        w = RunFileWriter.create({str(path)!r}, backend="sim", chain=chain, scans=[spec])
        w.write_point("ltr", 0, 1, np.ones(8), np.ones(8))
        w._f.close()
        f = h5py.File({str(path)!r}, "r+", libver="latest")  # what close() does next
        f.attrs["status"] = "complete"
        os._exit(9)
        """,
        tmp_path,
    )
    assert rc == 9
    assert not _plain_h5py_opens(path)
    before = _digest(path)
    run = read_run(path)  # through a cleared view
    assert run.scans["ltr"].done.tolist() == [[0, 1]]
    assert _digest(path) == before
    assert biafc(["repair", str(path)]) == 0
    assert _plain_h5py_opens(path)
    assert read_run(path).scans["ltr"].done.tolist() == [[0, 1]]


def test_a_kill_while_creating_leaves_nothing_under_the_run_name(tmp_path) -> None:
    path = tmp_path / "new.h5"
    rc = _python(
        f"""
        import os, numpy as np
        from protocols.runfile import RunFileWriter, ScanSpec, ChainInfo
        RunFileWriter._create_scan = staticmethod(lambda root, spec: os._exit(9))
        chain = ChainInfo(np.ones(3), 0.01, 5.0, 1e9, np.ones((3, 1)), np.ones((3, 1)))
        spec = ScanSpec("ltr", np.array([1.0]), "V", np.array([1], np.int32),
                        np.linspace(0, 1e-3, 8), 8e3, cycles=5)
        RunFileWriter.create({str(path)!r}, backend="sim", chain=chain, scans=[spec])
        """,
        tmp_path,
    )
    assert rc == 9
    assert not path.exists()  # the name stays free for the next run
    leftovers = list(tmp_path.glob(".new.h5.*.part"))
    assert len(leftovers) == 1
    from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec

    chain = ChainInfo(np.ones(3), 0.01, 5.0, 1e9, np.ones((3, 1)), np.ones((3, 1)))
    spec = ScanSpec(
        "ltr", np.array([1.0]), "V", np.array([1], np.int32), np.linspace(0, 1e-3, 8), 8e3, 5
    )
    RunFileWriter.create(path, backend="sim", chain=chain, scans=[spec]).close("aborted")
    assert _plain_h5py_opens(path)
    assert biafc(["repair", str(path)]) == 0
    assert not list(tmp_path.glob(".new.h5.*.part"))  # the dead creator's leftover is gone


def test_repair_rebuilds_a_file_that_takes_no_more_writes(
    proto_file, tmp_path, monkeypatch
) -> None:
    """Found by the fault campaign: a writer killed while closing (metadata half written
    outside SWMR) leaves a file that reads but refuses writes ("bad heap index"); repair then
    copies every object into a fresh file, losing no point."""
    from protocols.runfile import RunFileWriter

    killed = tmp_path / "heap.h5"
    _killed_run(proto_file, killed)
    done = _done(killed)
    real = RunFileWriter.open_existing.__func__  # type: ignore[attr-defined]
    calls: list[int] = []

    def refuses_once(cls, path, **kw):  # type: ignore[no-untyped-def]
        calls.append(1)
        if len(calls) == 1:
            raise OSError("Can't synchronously write data (bad heap index)")
        return real(cls, path, **kw)

    monkeypatch.setattr(RunFileWriter, "open_existing", classmethod(refuses_once))
    assert biafc(["repair", str(killed)]) == 0
    assert _plain_h5py_opens(killed) and read_run(killed).status == "aborted"
    for d, mask in _done(killed).items():
        np.testing.assert_array_equal(mask, done[d])
    assert not list(tmp_path.glob(".heap.h5.*.repair"))


#: loaded into the run's process (``sitecustomize``): SIGKILL it at the ``KILL_AFTER_RECORDS``-th
#: point whose records are flushed, before the file's flush that marks the point done
_KILL_HOOK = textwrap.dedent(
    """
    import os, signal
    import h5py
    _at = int(os.environ["KILL_AFTER_RECORDS"])
    _seen = [0, False]
    _ds_flush, _file_flush = h5py.Dataset.flush, h5py.File.flush
    def _ds(self):
        _ds_flush(self)
        if self.name.endswith("/drive"):
            _seen[0] += 1
            _seen[1] = True
    def _file(self):
        if _seen[1] and _seen[0] == _at:
            os.kill(os.getpid(), signal.SIGKILL)
        _seen[1] = False
        _file_flush(self)
    h5py.Dataset.flush, h5py.File.flush = _ds, _file
    """
)


def _killed_after_records(proto_file: Path, folder: Path, n: int) -> Path:
    """``folder/killed.h5``: a run_protocol process of ``proto_file`` on the simulated bench
    (seed 5), SIGKILLed once its ``n``-th point's records are flushed, before the file's flush
    that marks that point done (:data:`_KILL_HOOK`)."""
    hook = folder / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(_KILL_HOOK)
    killed = folder / "killed.h5"
    env = dict(os.environ, KILL_AFTER_RECORDS=str(n), PYTHONPATH=f"{hook}{os.pathsep}{ROOT}")
    proc = subprocess.run(
        [sys.executable, "-m", "daq.cli.run_protocol", str(proto_file), "--out", str(killed),
         "--seed", "5", "-q"],
        env=env, cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == -9, proc.stderr
    return killed


def test_a_kill_between_a_points_records_and_its_done_mark_loses_no_point(
    proto_file, tmp_path
) -> None:
    """A second reader: under SWMR a point's records are flushed before the file's flush that
    writes the superblock's end-of-file address and marks the point done. Killed between the
    two, the file held chunks past that address; --resume (or biafc repair) allocated over
    them and lost every measured point, or ended 'complete' with a file no tool read."""
    reference = tmp_path / "reference.h5"
    assert rp.main([str(proto_file), "--out", str(reference), "--seed", "5", "-q"]) == 0
    killed = _killed_after_records(proto_file, tmp_path, 3)
    assert rp.main(["--resume", str(killed), "-q"]) == 0
    a, b = read_run(reference), read_run(killed)
    assert b.status == "complete"
    for d, scan in a.scans.items():
        np.testing.assert_array_equal(scan.done, b.scans[d].done)
        np.testing.assert_array_equal(scan.velocity, b.scans[d].velocity)
    assert _plain_h5py_opens(killed)
    assert biafc(["repair", str(killed)]) == 0


def test_a_killed_sessions_missing_dem_runs_are_said_in_the_file(proto_file, tmp_path) -> None:
    """A reviewer: /simulation is written as the file closes, so a killed session's DEM runs
    are never recorded; after the resume the file listed the resume's runs as if they were
    all, its worst error estimate missing the killed session's. Now it says how many are
    missing."""
    killed = _killed_after_records(proto_file, tmp_path, 5)
    assert rp.main(["--resume", str(killed), "-q"]) == 0
    sim = read_run(killed).simulation
    assert sim["dem_runs"] == 3  # ltr at 2 Vpp, rtl at 1 and 2 Vpp: this session's
    assert sim["dem_runs_note"].startswith("1 (direction, amplitude) pair(s) with measured")
