"""The live views draw a 30 ms x 1 MS/s record quickly (decimated), and the CLI entry checks
its files before opening a window."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from daq.cli.biafc import main as biafc_main
from daq.gui.live_data import LiveData, ScanView
from daq.gui.views import LiveViews


def _big_point() -> dict[str, Any]:
    rate, dur = 1e6, 30e-3
    t = np.arange(int(rate * dur)) / rate
    v = 1e-3 * np.sin(2 * np.pi * 8.92e3 * t) * np.exp(-t / 5e-3)
    return {
        "direction": "ltr",
        "amplitude_index": 0,
        "cylinder_index": 0,
        "amplitude": 2e-6,
        "amplitude_units": "m",
        "cylinder": 1,
        "time_s": t,
        "velocity_m_per_s": v,
    }


def test_long_trace_redraw_is_fast(qtbot: Any) -> None:
    views = LiveViews()
    qtbot.addWidget(views)
    views.resize(1000, 600)
    views.show()
    live = LiveData()
    live.scans["ltr"] = ScanView.empty(
        "ltr", 8.92e3, np.array([2e-6]), "m", np.array([1, 2], np.int32), 30_000, 1e6
    )
    t0 = time.perf_counter()
    live.add_point(_big_point())
    views.redraw(live)
    qtbot.wait(1)
    dt = time.perf_counter() - t0
    assert views.trace.n_drawn <= 4002  # decimated, not 30 000 points
    assert views.spatial.n_rows == 1 and views.sweep.n_cells == 1
    assert dt < 0.5, f"a 30 ms x 1 MS/s point took {dt * 1e3:.0f} ms to draw"
    for _ in range(3):  # steady state: well under a frame budget of the 100 ms redraw timer
        live.add_point(_big_point())
        t0 = time.perf_counter()
        views.redraw(live)
        assert time.perf_counter() - t0 < 0.1


def test_biafc_gui_missing_file_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = biafc_main(["gui", "--protocol", str(tmp_path / "nope.yaml")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert "nope.yaml" in err and len(err.splitlines()) == 1


def test_paths_shown_relative_to_the_working_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from daq.gui.main_window import shown_path

    monkeypatch.chdir(tmp_path)
    assert shown_path(tmp_path / "runs" / "a.h5") == str(Path("runs") / "a.h5")
    outside = tmp_path.parent / "elsewhere.h5"
    assert shown_path(outside) == str(outside)


def test_the_bands_and_spectrum_follow_the_direction_being_measured(qtbot: Any) -> None:
    """During an rtl scan the Quasi-bands tab kept the ltr burst's 8.92 kHz, and the spectrum's
    title had no amplitude (a second reader, directions: both)."""
    views = LiveViews()
    qtbot.addWidget(views)
    live = LiveData()
    for d, f in (("ltr", 8.92e3), ("rtl", 6.63e3)):
        live.scans[d] = ScanView.empty(
            d, f, np.array([2e-6]), "m", np.array([1, 2], np.int32), 30_000, 1e6
        )
    views.show_chain(None, 8.92e3)
    live.add_point({**_big_point(), "direction": "rtl", "cylinder": 31})
    views.redraw(live)
    assert views.bands.input_line.value() == pytest.approx(6.63)
    assert "amplitude 2 um" in views.spectrum.plotItem.titleLabel.text


def test_the_maps_show_any_direction_and_amplitude_chosen(qtbot: Any) -> None:
    """The maps showed only the point being measured: after a run of both directions the ltr
    data could not be viewed in the window at all (a second reader)."""
    views = LiveViews()
    qtbot.addWidget(views)
    live = LiveData()
    for d, f in (("ltr", 8.92e3), ("rtl", 6.63e3)):
        live.scans[d] = ScanView.empty(
            d, f, np.array([1e-6, 2e-6]), "m", np.array([1, 2], np.int32), 30_000, 1e6
        )
    live.add_point({**_big_point(), "amplitude_index": 1})  # ltr, 2 um, cylinder 1
    live.add_point({**_big_point(), "direction": "rtl", "amplitude_index": 1, "cylinder": 31})
    views.redraw(live)
    assert "rtl" in views.spatial.plotItem.titleLabel.text  # following the run
    texts = [views.map_choice.itemText(i) for i in range(views.map_choice.count())]
    assert texts == ["maps: following the run", "ltr 1 um", "ltr 2 um", "rtl 1 um", "rtl 2 um"]
    views.map_choice.setCurrentIndex(2)  # ltr 2 um: redrawn at once
    assert "ltr, 2 um" in views.spatial.plotItem.titleLabel.text
    assert "(ltr)" in views.sweep.plotItem.titleLabel.text
    views.redraw(live)  # a new point does not take the choice away
    assert views.map_choice.currentText() == "ltr 2 um"


def test_the_live_map_leaves_cylinders_not_scanned_empty(qtbot: Any) -> None:
    """A scan of cylinders 1 and 8 filled rows 2-7 with their nearest neighbour's spectrum, as
    if measured (the figures' maps now leave such gaps too)."""
    views = LiveViews()
    qtbot.addWidget(views)
    live = LiveData()
    live.scans["ltr"] = ScanView.empty(
        "ltr", 8.92e3, np.array([2e-6]), "m", np.array([1, 8], np.int32), 30_000, 1e6
    )
    live.add_point(_big_point())
    live.add_point({**_big_point(), "cylinder_index": 1, "cylinder": 8})
    views.redraw(live)
    grid = views.spatial.image.image  # [rows = cylinders 1..8, F]
    measured = np.isfinite(grid).any(axis=1)
    assert list(np.nonzero(measured)[0] + 1) == [1, 8]


def test_a_failed_point_measured_on_resume_is_no_longer_counted(qtbot: Any) -> None:
    live = LiveData()
    live.scans["ltr"] = ScanView.empty(
        "ltr", 8.92e3, np.array([2e-6]), "m", np.array([1, 2], np.int32), 30_000, 1e6
    )
    live.add_failed({**_big_point(), "reason": "NaN"})
    live.add_failed({**_big_point(), "cylinder_index": 1, "cylinder": 2, "reason": "NaN"})
    assert live.n_failed == 2
    live.add_point(_big_point())  # the resume measured cylinder 1 after all
    assert live.n_failed == 1


def test_a_force_driven_run_is_labelled_in_newtons(qtbot: Any) -> None:
    """A `biafc simulate --amplitude 12N` file (amplitudes in N) was labelled Vpp everywhere:
    anything not "m" was taken for the generator's volts."""
    from daq.gui.panels import RunPanel

    views = LiveViews()
    qtbot.addWidget(views)
    live = LiveData()
    live.scans["ltr"] = ScanView.empty(
        "ltr", 8.92e3, np.array([0.5, 12.0]), "N", np.array([1, 2], np.int32), 30_000, 1e6
    )
    for ai, amp in ((0, 0.5), (1, 12.0)):
        live.add_point({**_big_point(), "amplitude_index": ai, "amplitude": amp,
                        "amplitude_units": "N"})  # fmt: skip
    views.redraw(live)
    titles = [
        views.trace.p_vel.titleLabel.text,
        views.spectrum.plotItem.titleLabel.text,
        views.spatial.plotItem.titleLabel.text,
    ]
    assert all("12 N" in t and "Vpp" not in t for t in titles), titles
    ticks = [t for _, t in views.sweep.getAxis("left")._tickLevels[0]]
    assert ticks == ["0.5 N", "12 N"], ticks
    texts = [views.map_choice.itemText(i) for i in range(views.map_choice.count())]
    assert texts[1:] == ["ltr 500 mN", "ltr 12 N"]
    panel = RunPanel()
    qtbot.addWidget(panel)
    progress = {"total": 2, "done": 1, "amplitude": 12.0, "amplitude_units": "N"}
    panel.show_progress({**progress, "direction": "ltr", "cylinder": 1, "elapsed_s": 1.0,
                         "eta_s": 1.0})  # fmt: skip
    assert "amplitude 12 N" in panel.where_label.text()
    from daq.gui.views import amplitude_text

    assert amplitude_text(1.0, "V") == "1 Vpp" and amplitude_text(2e-6, "m") == "2 um"


def test_an_amplitude_without_a_unit_or_a_number_is_labelled_as_before() -> None:
    """A reviewer: a file that names no amplitude unit (read as "") showed a bare number where
    it had shown Vpp, and a NaN amplitude read "nan m"."""
    from daq.gui.views import amplitude_text

    assert amplitude_text(1.0, "") == "1 Vpp"
    assert amplitude_text(float("nan"), "m") == "-"
    assert amplitude_text(12.0, "N") == "12 N" and amplitude_text(2e-6, "m") == "2 um"
