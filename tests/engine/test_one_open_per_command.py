"""Each command opens its input file once (issue 18): every open of a truncated or damaged file
left by a killed writer waits before it refuses (the header probe's 0.5 s grace for a live
writer, the bounded SWMR retry), so ``biafc figures`` asking "is it a study?" and then reading
the file as a run, or ``biafc repair`` and ``--resume`` doing the same, paid that wait twice.
Counted here: the header probes and SWMR opens of one command, and its refusal, unchanged."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import protocols.runfile as runfile
from daq.cli.biafc import main as biafc
from daq.cli.run_protocol import main as run_protocol
from protocols.recover import has_consistency_flags
from protocols.runfile import RunFileWriter, ScanSpec

from .helpers import chain_info


def _writer(path: Path) -> RunFileWriter:
    t = np.arange(2000) / 200e3
    spec = ScanSpec("ltr", np.array([1e-6, 2e-6]), "m", np.arange(1, 4, dtype=np.int32), t,
                    8920.0, cycles=21.0, drive_units="m")  # fmt: skip
    return RunFileWriter.create(path, backend="sim", chain=chain_info(), scans=[spec])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Bytes of a complete run file ("good") and of one whose writer still held it after 3
    points ("killed": its consistency flags set, as a killed writer leaves them)."""
    d = tmp_path_factory.mktemp("runs")
    w = _writer(d / "live.h5")
    try:
        for c in range(3):
            w.write_point("ltr", 0, c, np.sin(np.arange(2000) * 0.3), np.cos(np.arange(2000) * 0.3))
        killed = (d / "live.h5").read_bytes()
    finally:
        w.close("complete")
    good = (d / "live.h5").read_bytes()
    (d / "k.h5").write_bytes(killed)
    assert has_consistency_flags(d / "k.h5")
    return {"good": good, "killed": killed}


def _zeroed(data: bytes) -> bytes:
    b = bytearray(data)
    b[100:600] = b"\0" * 500  # metadata past the superblock: HDF5 finds it, under SWMR
    return bytes(b)


DAMAGES: dict[str, tuple[Callable[[bytes], bytes], str]] = {
    "cut_to_1024": (lambda d: d[:1024], "truncated"),
    "cut_by_100": (lambda d: d[:-100], "truncated"),
    "bytes_100_600_zeroed": (_zeroed, "damaged"),
}


@pytest.fixture
def opens(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, int]]:
    """How often the header probe (its grace: a live writer) and the bounded SWMR open (its
    retry) ran: each open of a file pays them."""
    counts = {"probe": 0, "swmr": 0}

    def counted(name: str, fn: Callable[[Any], Any]) -> Callable[[Any], Any]:
        def call(path: Any) -> Any:
            counts[name] += 1
            return fn(path)

        return call

    monkeypatch.setattr(runfile, "probe_hdf5", counted("probe", runfile.probe_hdf5))
    monkeypatch.setattr(runfile, "open_swmr", counted("swmr", runfile.open_swmr))
    yield counts


def _refusal(capsys: pytest.CaptureFixture[str], path: Path, word: str) -> None:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and word in lines[0], lines


@pytest.mark.parametrize("name", list(DAMAGES))
def test_figures_opens_a_damaged_killed_file_once(
    files: dict[str, bytes],
    tmp_path: Path,
    opens: dict[str, int],
    capsys: pytest.CaptureFixture[str],
    name: str,
) -> None:
    damage, word = DAMAGES[name]
    path = tmp_path / f"{name}.h5"
    path.write_bytes(damage(files["killed"]))
    assert biafc(["figures", str(path), "--out", str(tmp_path / "figs")]) == 2
    _refusal(capsys, path, word)
    assert opens["probe"] == 1 and opens["swmr"] <= 1, opens  # twice each before
    assert not (tmp_path / "figs").exists()


@pytest.mark.parametrize("command", ["repair", "resume"])
def test_repair_and_resume_open_a_damaged_killed_file_once(
    files: dict[str, bytes],
    tmp_path: Path,
    opens: dict[str, int],
    capsys: pytest.CaptureFixture[str],
    command: str,
) -> None:
    for name, (damage, word) in DAMAGES.items():
        path = tmp_path / f"{command}_{name}.h5"
        path.write_bytes(damage(files["killed"]))
        opens.update(probe=0, swmr=0)
        if command == "repair":
            assert biafc(["repair", str(path)]) == 2
        else:
            assert run_protocol(["--resume", str(path)]) == 2
        _refusal(capsys, path, word)
        assert opens["probe"] == 1 and opens["swmr"] <= 1, (name, opens)  # twice each before


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"a text file\n", "not an HDF5 file"), (None, "does not exist")],
)
def test_figures_refuses_no_run_file_as_before(
    tmp_path: Path,
    opens: dict[str, int],
    capsys: pytest.CaptureFixture[str],
    content: bytes | None,
    message: str,
) -> None:
    path = tmp_path / "x.h5"
    if content is not None:
        path.write_bytes(content)
    assert biafc(["figures", str(path), "--out", str(tmp_path / "figs")]) == 2
    _refusal(capsys, path, message)
    assert opens["probe"] <= 1 and opens["swmr"] == 0, opens


def test_figures_reads_a_good_run_file_through_one_open(
    files: dict[str, bytes], tmp_path: Path, opens: dict[str, int]
) -> None:
    path = tmp_path / "good.h5"
    path.write_bytes(files["good"])
    assert biafc(["figures", str(path), "--out", str(tmp_path / "figs")]) == 0
    assert (tmp_path / "figs" / "summary.json").is_file()
    assert opens == {"probe": 1, "swmr": 0}  # 3 probes before (kind, format, read)


def test_study_options_on_a_damaged_run_file_are_still_named_first(
    files: dict[str, bytes], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cut.h5"
    path.write_bytes(files["killed"][:1024])
    assert biafc(["figures", str(path), "--x", "diameter"]) == 2
    assert capsys.readouterr().err.strip().endswith("--x applies only to a study output")


def test_a_run_file_is_told_from_a_study_without_the_study_schema(
    files: dict[str, bytes], tmp_path: Path
) -> None:
    """``read_output`` tells a study output by its root's ``format``; a run file is read without
    importing the study schema (``protocols.study``, pydantic: 0.15-0.18 s of every ``biafc
    figures`` of a run file, imported at the top of ``protocols.outputfile`` before)."""
    import subprocess
    import sys

    path = tmp_path / "good.h5"
    path.write_bytes(files["good"])
    code = (
        "import sys; import daq.cli.figures; from protocols.outputfile import read_output; "
        f"d = read_output({str(path)!r}); assert type(d).__name__ == 'RunData', type(d); "
        "assert 'protocols.study' not in sys.modules, 'the study schema was imported'"
    )
    root = Path(__file__).resolve().parents[2]
    subprocess.run([sys.executable, "-c", code], check=True, cwd=root)
