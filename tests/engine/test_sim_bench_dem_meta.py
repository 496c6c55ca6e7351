"""The simulated bench records its DEM runs' error indicators in the run file's /simulation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from daq.cli import run_protocol as rp
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec, read_run

ROOT = Path(__file__).resolve().parents[2] / "protocols"


def test_close_sets_simulation_attrs(tmp_path: Path) -> None:
    chain = ChainInfo(np.ones(2), 0.01, 5.0, 1e9, np.ones((2, 1)), np.ones((2, 1)))
    scan = ScanSpec("ltr", np.array([1.0]), "m", np.array([1, 2], np.int32), np.arange(4.0), 1e3)
    w = RunFileWriter.create(tmp_path / "r.h5", backend="sim", chain=chain, scans=[scan])
    w.close("complete", simulation={"integrator": "strang", "error_estimate_rel": 1e-5})
    run = read_run(tmp_path / "r.h5")
    assert run.status == "complete"
    assert run.simulation == {"integrator": "strang", "error_estimate_rel": 1e-5}


def test_sim_bench_run_file_holds_dem_error_estimates(tmp_path: Path) -> None:
    out = tmp_path / "smoke.h5"
    assert rp.main([str(ROOT / "smoke.yaml"), "--out", str(out), "--quiet"]) == 0
    run = read_run(out)
    sim = run.simulation
    assert sim["integrator"] == "blanes-moan4" and sim["order"] == 4
    assert 0 < sim["dt_s"] <= 2e-6
    assert 0 < sim["error_estimate_rel"] < 1e-3
    # the simulated bench's chain is damped: most of the input work is dissipated by the end
    assert 0.5 < sim["work_not_in_chain_rel"] < 1.0
    assert "energy_residual_rel" not in sim
    runs = json.loads(sim["dem_runs_json"])
    scan = run.scans["ltr"]
    assert len(runs) == sim["dem_runs"] == len(scan.amplitudes)
    assert {r["direction"] for r in runs} == {"ltr"}
    assert all(r["amplitude_units"] == "m" and r["amplitude"] > 0 for r in runs)
    assert max(r["error_estimate_rel"] for r in runs) == sim["error_estimate_rel"]


def _aborted_after_the_first_amplitude(out: Path) -> None:
    """A smoke run on the simulated bench into ``out``, aborted after its first 3 points."""
    from daq.connect import connect_bench
    from daq.engine import EventKind, RunEngine
    from protocols.bench import load_bench
    from protocols.schema import load_protocol

    inst = connect_bench(load_bench())
    eng = RunEngine(load_protocol(ROOT / "smoke.yaml"), load_bench(), inst, out)
    done = []

    def stop_after_the_first_amplitude(e: object) -> None:
        if getattr(e, "kind", None) == EventKind.POINT_DONE:
            done.append(e)
            if len(done) == 3:
                eng.abort("test: after the first amplitude")

    eng.subscribe(stop_after_the_first_amplitude)
    try:
        assert eng.run().status == "aborted"
    finally:
        inst.close()


def test_a_resumed_run_keeps_the_earlier_sessions_dem_runs(tmp_path: Path) -> None:
    """A second reader: after a resume, /simulation described the resume's own DEM runs only
    (dem_runs 1, the second amplitude), so the worst error estimate of the points measured
    before the interruption was lost from the file."""
    out = tmp_path / "run.h5"
    _aborted_after_the_first_amplitude(out)
    first = json.loads(read_run(out).simulation["dem_runs_json"])
    assert [r["amplitude"] for r in first] == [5e-07]
    assert rp.main(["--resume", str(out), "--quiet"]) == 0
    sim = read_run(out).simulation
    runs = json.loads(sim["dem_runs_json"])
    assert [r["amplitude"] for r in runs] == [5e-07, 3e-06] and sim["dem_runs"] == 2
    assert sim["error_estimate_rel"] == max(r["error_estimate_rel"] for r in runs)


def test_a_resume_by_another_model_version_is_a_bench_difference(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second reader: a simulated run resumed after the DEM kernel's arithmetic changed
    was continued without a word, its points made by two kernels. The model version is in the
    snapshot, and another is a bench difference: refused, or recorded with
    --accept-bench-change."""
    from sim_backend.dem import versions

    out = tmp_path / "run.h5"
    _aborted_after_the_first_amplitude(out)
    import h5py

    with h5py.File(out, "r") as f:
        model = json.loads(f["snapshot"].attrs["json"])["simulation_model"]
    assert model["model_version"] == versions.model_version()
    monkeypatch.setattr(versions, "model_version", lambda: "kernel 9: another; modes 2")
    assert rp.main(["--resume", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "simulated bench model: " in err and "'kernel 9: another; modes 2' now" in err, err
    assert (
        "was measured with another simulated-bench model" in err and "on another bench" not in err
    )
    assert read_run(out).status == "aborted"  # refused: not touched
    assert rp.main(["--resume", str(out), "--quiet", "--accept-bench-change"]) == 0
    overrides = json.loads(read_run(out).attrs["bench_overrides_json"])
    assert any("simulated bench model" in d for d in overrides[-1]["differences"])


def test_an_old_simulated_run_file_says_why_it_needs_accept_bench_change(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reviewer: a file made before the model version was recorded was refused as "started
    on another bench ... resume on the same bench", which the user (on the same bench) could
    not act on."""
    import h5py

    out = tmp_path / "run.h5"
    _aborted_after_the_first_amplitude(out)
    with h5py.File(out, "r+") as f:
        snap = json.loads(f["snapshot"].attrs["json"])
        del snap["simulation_model"]["model_version"]
        f["snapshot"].attrs["json"] = json.dumps(snap)
    assert rp.main(["--resume", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "not recorded in" in err and "made before run files recorded it" in err, err
    assert "give --accept-bench-change to continue it with this one" in err
    assert "resume on the same bench" not in err
