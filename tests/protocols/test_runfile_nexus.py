"""Run files are valid NeXus: nexusformat opens them with an NXentry whose default NXdata plots
velocity against its axes, each with units, and its validator finds no error; the biafc layout
(read_run) is unchanged. Also: the burst's cycles and width are both stated (no NaN)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec, read_run

nx = pytest.importorskip("nexusformat.nexus")

N = 5


def _chain() -> ChainInfo:
    return ChainInfo(
        lengths_m=np.linspace(0.09, 0.11, N),
        diameter_m=0.0136,
        f0_N=5.0,
        beta_c=4.08e9,
        onset_Hz=np.full((N, 2), 7000.0),
        cutoff_Hz=np.full((N, 2), 9000.0),
    )


def _write(path: Path, **burst: float) -> Path:
    t = np.arange(64) / 100e3
    specs = [
        ScanSpec("ltr", np.array([1e-6, 2e-6]), "m", np.arange(1, N + 1, dtype=np.int32), t,
                 8920.0, averages=2, drive_units="m", **burst),  # type: ignore[arg-type]
        ScanSpec("rtl", np.array([1e-6]), "m", np.array([1, N], dtype=np.int32), t, 6630.0,
                 drive_units="m", **burst),  # type: ignore[arg-type]
    ]  # fmt: skip
    snapshot = {"generator": {"model": "33500B"}, "vibrometer": {"range": "VD-09"}, "stage": {}}
    w = RunFileWriter.create(
        path, backend="sim", chain=_chain(), scans=specs, snapshot=snapshot,
        protocol_yaml="name: x\n", bench_yaml="name: y\n",
    )  # fmt: skip
    w.write_point("ltr", 0, 0, np.sin(t * 1e4), np.cos(t * 1e4))
    w.close("aborted")
    return path


def test_run_file_opens_in_nexusformat_with_default_plot_and_units(tmp_path: Path) -> None:
    path = _write(tmp_path / "run.h5", cycles=5.0)
    root = nx.nxload(str(path))
    try:
        assert root.nxclass == "NXroot"
        entries = [g for g in root.NXentry]
        assert [e.nxname for e in entries] == ["scan"]
        entry = entries[0]
        assert entry.NXinstrument and entry.NXsample
        assert {g.nxname for g in entry.instrument.NXdetector} == {"vibrometer"}
        assert entry.sample.lengths_m.attrs["units"] == "m"
        data = root.plottable_data  # root -> default entry -> default NXdata
        assert data.nxclass == "NXdata" and data.nxpath == "/scan/ltr"
        assert data.nxsignal.nxname == "velocity"
        assert data.nxsignal.attrs["units"] == "m/s"
        axes = data.nxaxes
        assert [a.nxname for a in axes] == ["amplitudes", "cylinders", "time"]
        assert [a.attrs["units"] for a in axes] == ["m", "", "s"]
        assert all(a.attrs["long_name"] for a in axes)
        assert data.nxsignal.shape == (2, N, 64)
        assert {d.nxname for d in entry.NXdata} == {"ltr", "rtl"}
        _, n_errors = root.check(level="error")
        assert n_errors == 0
    finally:
        root.nxfile.close()


def test_nexus_view_keeps_the_biafc_layout(tmp_path: Path) -> None:
    run = read_run(_write(tmp_path / "run.h5", cycles=5.0))
    assert set(run.scans) == {"ltr", "rtl"}
    assert run.status == "aborted"
    np.testing.assert_array_equal(run.chain.lengths_m, np.linspace(0.09, 0.11, N))
    assert run.scans["ltr"].done[0, 0] == 1 and run.scans["ltr"].done.sum() == 1


@pytest.mark.parametrize(("given", "cycles", "width_s"),
                         [({"cycles": 5.0}, 5.0, 5.0 / 8920.0 / 6.0),
                          ({"width_s": 1e-4}, 6e-4 * 8920.0, 1e-4)])  # fmt: skip
def test_burst_cycles_and_width_are_both_stated(
    tmp_path: Path, given: dict[str, float], cycles: float, width_s: float
) -> None:
    """``width_s`` was NaN in the file (and in every reader's summary) when cycles were given."""
    import h5py

    path = _write(tmp_path / "run.h5", **given)
    with h5py.File(path, "r") as f:
        attrs = f["scan/ltr"].attrs
        assert float(attrs["cycles"]) == pytest.approx(cycles)
        assert float(attrs["width_s"]) == pytest.approx(width_s)
    scan = read_run(path).scans["ltr"]
    assert scan.cycles == pytest.approx(cycles) and scan.width_s == pytest.approx(width_s)
