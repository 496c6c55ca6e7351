"""A run file read with plain h5py, as a physicist would a year later without this software:
what the ``done`` codes mean, the unit of the log's time, why a point failed, the instruments'
settings after they were set up (not only at creation), the vibrometer sensitivity and the
decoder delay of every point, and the history of the resumes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.engine import RunEngine
from protocols.runfile import PointState, read_run

from . import fakes
from .fakes import FakeWorld, Faults, fake_bench


def _run(protocol, bench, out, world=None, **kw):  # type: ignore[no-untyped-def]
    eng = RunEngine(protocol, bench, fake_bench(world or FakeWorld()), out, **kw)
    return eng.run()


def test_done_codes_log_time_unit_and_each_failed_points_reason_are_in_the_file(
    protocol, bench, out: Path
) -> None:
    res = _run(protocol, bench, out, FakeWorld(faults=Faults(nan_reads=3)))
    assert res.status == "failed" and res.n_failed == 1
    with h5py.File(out, "r") as f:
        done = f["scan/ltr/done"]
        assert done.attrs["codes"].startswith("0 not measured, 1 done")
        assert "2 failed" in done.attrs["codes"]
        assert "unix epoch" in f["log"].attrs["time_units"]
        assert "UTC" in f["log"].attrs["time_units"]
        reason = f["scan/ltr/fail_reason"].asstr()[...]
        assert reason.shape == done.shape
        assert "NaN" in reason[0, 0], reason[0, 0]
        assert not any(reason.flat[1:]) and not any(f["scan/rtl/fail_reason"].asstr()[...].flat)
    scan = read_run(out).scans["ltr"]
    assert scan.done[0, 0] == PointState.FAILED and "NaN" in scan.fail_reason[0, 0]


def test_a_failed_point_measured_at_a_resume_loses_its_reason(protocol, bench, out) -> None:
    _run(protocol, bench, out, FakeWorld(faults=Faults(nan_reads=3)))
    assert _run(protocol, bench, out, resume=True).status == "complete"
    scan = read_run(out).scans["ltr"]
    assert np.all(scan.done == PointState.DONE) and not any(scan.fail_reason.flat)


def _as_an_old_file(path: Path) -> None:
    """Strip from ``path`` the fields added to the layout after the first files."""
    with h5py.File(path, "r+") as f:
        for d in ("ltr", "rtl"):
            g = f["scan"][d]
            for name in ("fail_reason", "sensitivity_m_per_s_per_V", "decoder_delay_undone_s"):
                if name in g:
                    del g[name]
            g["done"].attrs.pop("codes", None)
            for key in ("decoder_delay_undone_s", "decoder_delay_note"):
                g["velocity"].attrs.pop(key, None)
        for key in ("time_units", "description"):
            f["log"].attrs.pop(key, None)
        if "armed" in f["snapshot"]:
            del f["snapshot/armed"]


def test_a_file_without_the_new_fields_reads_and_resumes(protocol, bench, out: Path) -> None:
    _run(protocol, bench, out, FakeWorld(faults=Faults(stall_on_move=7)))
    _as_an_old_file(out)
    old = read_run(out)
    assert old.armed_snapshots == []
    assert old.scans["ltr"].fail_reason.shape == (2, 3) and not any(
        old.scans["ltr"].fail_reason.flat
    )
    assert _run(protocol, bench, out, resume=True).status == "complete"
    with h5py.File(out, "r") as f:
        assert "codes" in f["scan/ltr/done"].attrs and "time_units" in f["log"].attrs
        armed = f["snapshot/armed"]["direction"]
        assert [d.decode() for d in armed] == ["rtl", "rtl"]  # the resume's armings
        assert f["scan/rtl/fail_reason"].shape == (2, 3)
        # 7 points before (all of ltr, the first of rtl): unknown; the resume's: known
        assert np.all(np.isnan(f["scan/ltr/sensitivity_m_per_s_per_V"][...]))
        sens = f["scan/rtl/sensitivity_m_per_s_per_V"][...].ravel()
        assert np.isnan(sens[0]) and np.all(sens[1:] == fakes.SENS)
        assert "decoder_delay_undone_s" not in f["scan/ltr/velocity"].attrs  # not known then
    scan = read_run(out).scans["rtl"]
    assert np.isnan(scan.decoder_delay_undone_s[0, 0]) and scan.decoder_delay_undone_s[1, 0] > 0


def test_each_points_sensitivity_and_the_decoder_delay_undone_are_in_the_file(
    protocol, bench, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The sensitivity and the decoder delay were read at every point and kept nowhere: a
    resume on another vibrometer range left no trace of which points it scaled."""
    out = tmp_path / "run.h5"
    _run(protocol, bench, out, FakeWorld(faults=Faults(stall_on_move=7)))
    monkeypatch.setattr(fakes, "SENS", 0.125)  # resumed on another range
    monkeypatch.setattr(fakes, "DELAY_S", 7.3e-6)
    assert _run(protocol, bench, out, resume=True).status == "complete"
    with h5py.File(out, "r") as f:
        v = f["scan/ltr/velocity"]
        assert v.attrs["decoder_delay_undone_s"] == 20e-6  # at the start
        assert "undone" in v.attrs["decoder_delay_note"]
        ltr, rtl = f["scan/ltr"], f["scan/rtl"]
        assert ltr["sensitivity_m_per_s_per_V"].attrs["units"] == "m/s/V"
        assert ltr["decoder_delay_undone_s"].attrs["units"] == "s"
        sens = np.concatenate([ltr["sensitivity_m_per_s_per_V"][...].ravel(),
                               rtl["sensitivity_m_per_s_per_V"][...].ravel()])  # fmt: skip
        delay = np.concatenate([ltr["decoder_delay_undone_s"][...].ravel(),
                                rtl["decoder_delay_undone_s"][...].ravel()])  # fmt: skip
    # order: direction, amplitude, cylinder; 7 points before the stall, 5 after the resume
    assert list(sens) == [0.05] * 7 + [0.125] * 5
    assert list(delay) == [20e-6] * 7 + [7.3e-6] * 5
    scan = read_run(out).scans["rtl"]
    assert scan.sensitivity_m_per_s_per_V[1, 2] == 0.125


def test_the_instruments_as_set_up_are_kept_at_every_arming_and_after_a_resume(
    protocol, bench, out: Path
) -> None:
    """/snapshot was taken once, at creation, before the generator was set up, and a resume
    took none: after a resume on another vibrometer range the file still named the first."""
    from protocols.bench import parse_bench

    _run(protocol, bench, out, FakeWorld(faults=Faults(stall_on_move=7)))
    other = parse_bench(bench.text.replace("VD-09 50mm/s/V", "VD-09 10mm/s/V"), "other.yaml")
    res = _run(protocol, other, out, resume=True, accept_bench_change=True)
    assert res.status == "complete", res.reason
    with h5py.File(out, "r") as f:
        first = f["snapshot"].attrs["json"]
        armed = f["snapshot/armed"]
        assert "generator's snapshot()" in armed.attrs["description"]
        assert "unix epoch" in armed.attrs["time_units"]
        rows = armed[...]
    # ltr A1, ltr A2, rtl A1 before the stall; rtl A1 again and rtl A2 after the resume
    said = [(r["direction"].decode(), int(r["amplitude_index"])) for r in rows]
    assert said == [("ltr", 0), ("ltr", 1), ("rtl", 0), ("rtl", 0), ("rtl", 1)]
    assert list(rows["amplitude"]) == [1.0, 2.0, 1.0, 1.0, 2.0]
    assert np.all(np.diff(rows["time"]) >= 0)
    ranges = [json.loads(r["json"])["read_back"]["vibrometer"]["range"] for r in rows]
    assert ranges == ["VD-09 50mm/s/V"] * 3 + ["VD-09 10mm/s/V"] * 2
    assert json.loads(first)["read_back"]["vibrometer"]["range"] == "VD-09 50mm/s/V"  # kept
    snaps = read_run(out).armed_snapshots
    assert [s["direction"] for s in snaps] == ["ltr", "ltr", "rtl", "rtl", "rtl"]
    assert snaps[-1]["snapshot"]["read_back"]["vibrometer"] == {"range": "VD-09 10mm/s/V"}


def test_the_generators_read_back_burst_reaches_the_file_on_the_simulated_bench(
    tmp_path: Path,
) -> None:
    from daq.cli import run_protocol as rp

    smoke = Path(__file__).resolve().parents[2] / "protocols" / "smoke.yaml"
    out = tmp_path / "smoke.h5"
    assert rp.main([str(smoke), "--out", str(out), "--quiet"]) == 0
    run = read_run(out)
    assert "read_back" not in run.snapshot["generator"]["channels"]["1"]  # before any set-up
    held = [s["snapshot"]["generator"]["channels"]["1"]["read_back"] for s in run.armed_snapshots]
    assert len(held) == 2 and all(h["load_ohm"] for h in held)
    assert 0 < held[0]["amplitude_Vpp"] < held[1]["amplitude_Vpp"]  # 0.5 um, then 3 um
    assert held[0]["sample_rate_Hz"] > 0


def _stamp_ok(text: str) -> bool:
    """ISO 8601 in UTC, to the second, as the root's ``created``: 2026-11-28T13:58:46+00:00."""
    from datetime import datetime, timedelta

    t = datetime.fromisoformat(text)
    return text.endswith("+00:00") and len(text) == 25 and t.utcoffset() == timedelta(0)


def test_each_resume_keeps_its_start_and_the_bench_text_it_ran_with(
    protocol, bench, out: Path
) -> None:
    """resumes_json entries had no time (the root's ``resumed`` keeps only the last) and the
    bench text of a resume was kept only for the differences the resume check compares."""
    from protocols.bench import parse_bench

    stall = {"faults": Faults(stall_on_move=3)}
    _run(protocol, bench, out, FakeWorld(**stall))
    # 1: the same bench; 2: another name only (not compared, not refused); 3: another range
    renamed = parse_bench(bench.text.replace(f"name: {bench.bench.name}", "name: bench B"), "b")
    assert renamed.text != bench.text
    ranged = parse_bench(bench.text.replace("VD-09 50mm/s/V", "VD-09 10mm/s/V"), "c")
    assert _run(protocol, bench, out, FakeWorld(**stall), resume=True).status == "failed"
    assert _run(protocol, renamed, out, FakeWorld(**stall), resume=True).status == "failed"
    res = _run(protocol, ranged, out, resume=True, accept_bench_change=True)
    assert res.status == "complete", res.reason
    with h5py.File(out, "r") as f:
        root = {k: f.attrs[k] for k in ("created", "started", "resumed", "finished")}
        resumes = json.loads(f.attrs["resumes_json"])
        overrides = json.loads(f.attrs["bench_overrides_json"])
    assert all(_stamp_ok(v) for v in root.values()), root
    assert len(resumes) == 3 and all(_stamp_ok(r["started"]) for r in resumes)
    assert resumes[-1]["started"] == root["resumed"]
    assert [r.get("bench_yaml") for r in resumes] == [None, renamed.text, ranged.text]
    assert _stamp_ok(overrides[0]["time"]) and overrides[0]["time"] == resumes[-1]["started"]


def test_band_columns_are_named_and_the_run_log_stamps_carry_their_zone(tmp_path: Path) -> None:
    """/chain/onset_Hz [31, 3] did not say what its columns were, and RUN.log's lines were in
    local time without a zone beside the file's UTC stamps (a second reader)."""
    import re

    from daq.cli.run_protocol import main as run_protocol
    from daq.logsetup import log_path_for

    out = tmp_path / "smoke.h5"
    assert run_protocol(["smoke.yaml", "--out", str(out), "-q"]) == 0
    with h5py.File(out, "r") as f:
        for name in ("onset_Hz", "cutoff_Hz"):
            axes = f["chain"][name].attrs["axes"]
            assert "row n is cylinder n + 1" in axes and "acoustic band" in axes
    lines = log_path_for(out).read_text().splitlines()
    stamp = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d ")
    assert lines and all(stamp.match(line) for line in lines if line[:2] == "20"), lines[:2]
    assert stamp.match(lines[0])


def test_a_vibrometer_dead_at_an_arming_ends_the_run_at_its_first_timeout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer: the per-arming snapshot asked every instrument everything, swallowing each
    error, so a dead vibrometer cost 7 timeouts (22 s simulated) before the run stopped."""
    from daq.cli import run_protocol as rp
    from daq.engine import engine as eng
    from sim_backend.emulators import transport
    from sim_backend.simbench import emulated

    seen: dict[str, Any] = {"timeouts": []}
    sync = emulated.EmulatedInstruments.sync

    def keep(self: Any, which: str) -> None:
        sync(self, which)
        seen["inst"] = self

    timeout = transport.SimTransport._timeout

    def count(self: Any, what: str) -> Any:
        seen["timeouts"].append(what)
        return timeout(self, what)

    arm = eng.RunEngine._arm_generator

    def dies_at_the_second(self: Any, point: Any) -> Any:
        if point.amplitude_index == 1:
            seen["inst"].vibrometer.responsive = False
        return arm(self, point)

    monkeypatch.setattr(emulated.EmulatedInstruments, "sync", keep)
    monkeypatch.setattr(transport.SimTransport, "_timeout", count)
    monkeypatch.setattr(eng.RunEngine, "_arm_generator", dies_at_the_second)
    smoke = Path(__file__).resolve().parents[2] / "protocols" / "smoke.yaml"
    assert rp.main([str(smoke), "--out", str(tmp_path / "s.h5"), "--quiet"]) == 1
    assert seen["timeouts"] == ["Get,VeloDec,1,Name"]


def test_a_reopen_that_fails_leaves_the_files_status_and_outcome(
    protocol, bench, out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer: the re-open wrote status "running" and removed the outcome before the steps
    that can fail, so a resume refused there left the file "running" (and open)."""
    import protocols.runfile as runfile

    _run(protocol, bench, out, FakeWorld(faults=Faults(nan_reads=3)))

    def full(f: Any) -> None:
        raise OSError("No space left on device")

    monkeypatch.setattr(runfile, "_require_file_fields", full)
    with pytest.raises(OSError, match="No space left"):
        runfile.RunFileWriter.open_existing(out, resumed=True)
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "failed" and f.attrs["outcome"].startswith("finished with")
