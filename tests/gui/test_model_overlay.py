"""The live views' "model" overlay: off by default, on it draws the DEM's prediction for the
point shown (its spectrum, every cylinder's peak on the spatial-frequency map)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from analysis.model_overlay import ModelOverlay
from analysis.model_run import chain_spec_of_run, predict, run_setup
from analysis.spectra import amplitude_spectrum
from analysis.synthetic_scan import write_synthetic_scan
from daq.gui.main_window import MainWindow
from protocols.runfile import read_run
from sim_backend.dem import build_chain, default_chain_spec

from .conftest import make_assembler


def _scan(tmp_path: Path) -> Path:
    return write_synthetic_scan(
        tmp_path / "scan.h5",
        true_spec=default_chain_spec(),
        amplitudes_m=(2e-6,),
        directions=("ltr",),
        cylinders=(1, 8, 16, 24, 31),
        duration_s=6e-3,
    )


def test_overlay_predicts_what_compare_predicts(tmp_path: Path) -> None:
    run = read_run(_scan(tmp_path))
    scan = run.scans["ltr"]
    ov = ModelOverlay.for_run(run)
    pred = ov.predict("ltr", float(scan.amplitudes[0]), scan.amplitude_units, scan.time_s)
    ref = predict(run_setup(run), build_chain(chain_spec_of_run(run)))["ltr"][0]  # [C, S]
    want = amplitude_spectrum(ref, scan.sample_rate_Hz).magnitude
    got = pred.magnitude[np.asarray(scan.cylinders) - 1]
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12 * want.max())
    # the drive goes through the bench's gain and stroke
    assert ov.drive_SI(2e-6, "m") == 2e-6
    assert np.isclose(ov.drive_SI(4.0, "V"), 0.5 * 4.0 * 20.0 * 5e-8)
    assert ov.cached("ltr", float(scan.amplitudes[0]), "m", scan.time_s) is pred


def test_model_overlay_off_by_default_then_drawn(
    qtbot: Any, tmp_path: Path, screenshots: Path
) -> None:
    path = _scan(tmp_path)
    win = MainWindow(None, None, assembler=make_assembler())
    qtbot.addWidget(win)
    win.resize(1400, 900)
    win.show()
    with qtbot.waitCallback(timeout=30_000) as cb:
        win.open_run_file(path, on_done=cb)
    assert cb.args == [True]
    views = win.views
    assert not views.model_box.isChecked()
    assert not views.spectrum.model_curve.isVisible()
    assert not views.spatial.model_peaks.isVisible()
    views.setCurrentWidget(views.spectrum)
    views.model_box.setChecked(True)
    qtbot.waitUntil(lambda: views.spectrum.model_curve.isVisible(), timeout=60_000)
    x, y = views.spectrum.model_curve.xData, views.spectrum.model_curve.yData  # not log10
    assert x is not None and x.size > 10 and np.nanmax(y) > 0
    # the prediction's peak sits where the measured spectrum's does (same chain as the data)
    tr = win.live.last
    assert tr is not None
    f_meas = tr.freq_Hz[np.nanargmax(tr.magnitude)] / 1e3
    assert abs(x[np.nanargmax(y)] - f_meas) < 0.2
    assert views.spatial.model_peaks.isVisible() or not views.spatial.isVisible()
    assert len(views.spatial.model_peaks.data) >= 20
    views.grab().save(str(screenshots / "view_spectrum_model.png"))
    views.model_box.setChecked(False)
    assert not views.spectrum.model_curve.isVisible()
