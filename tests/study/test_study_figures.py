"""Study figures: phase diagrams, the ranked table, Fig. 4 from a study over alpha."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from analysis.study_maps import alpha_sweep_from_study, phase_map, rank_designs
from daq.cli.biafc import main
from protocols.studyfile import read_study

from .conftest import TINY


def test_a_phase_map_holds_each_cells_metric_at_the_fixed_values(serial_reference: Path) -> None:
    data = read_study(serial_reference)
    pm = phase_map(data, "asymmetry_ratio", "diameter", "preload", fixed={"amplitude": 2.1e-6})
    assert pm.fixed == {"amplitude": 2e-6} and pm.reduced == [] and pm.values.shape == (2, 3)
    for iy, f0 in enumerate(pm.y):
        for ix, d in enumerate(pm.x):
            cell = (
                (data.parameters["diameter"] == d)
                & (data.parameters["preload"] == f0)
                & (data.parameters["amplitude"] == 2e-6)
            )
            assert pm.values[iy, ix] == data.metrics["asymmetry_ratio"][cell][0]
    top = phase_map(data, "asymmetry_ratio", "diameter", "preload", reduce="max")
    assert top.reduced == ["amplitude"]
    assert np.all(top.values >= pm.values)
    with pytest.raises(ValueError, match="diamter"):
        phase_map(data, "asymmetry_ratio", "diamter", "preload")


def test_the_ranking_sorts_cells_by_the_target(serial_reference: Path) -> None:
    data = read_study(serial_reference)
    rows = rank_designs(data, "asymmetry_ratio", top=4)
    vals = [r["asymmetry_ratio"] for r in rows]
    assert vals == sorted(vals, reverse=True) and vals[0] == np.nanmax(
        data.metrics["asymmetry_ratio"]
    )
    low = rank_designs(data, "min:transmission_ltr", top=1)[0]
    assert low["transmission_ltr"] == np.nanmin(data.metrics["transmission_ltr"])
    assert set(rows[0]) >= {"rank", "cell", "diameter", "preload", "amplitude"}


def test_biafc_figures_draws_a_study(
    serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "s.h5"
    shutil.copy(serial_reference, src)
    out = tmp_path / "figs"
    argv = ["figures", str(src), "--fix", "amplitude=2um", "--metric", "asymmetry_ratio",
            "--metric", "efficiency_rtl", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "best designs for largest asymmetry_ratio" in text
    for name in ("map_asymmetry_ratio.png", "map_efficiency_rtl.pdf", "best_designs.txt"):
        assert (out / name).stat().st_size > 0
    assert main(["figures", str(src), "--fix", "amplitude=2V", "--out", str(out)]) == 2


def test_biafc_figures_opens_a_study_once(
    serial_reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One open per command (issue 18): each open of a damaged file waits out its grace
    before it refuses; asking "is it a study?" first opened the file twice."""
    import protocols.runfile as runfile

    probes: list[object] = []
    probe = runfile.probe_hdf5
    monkeypatch.setattr(runfile, "probe_hdf5", lambda p: probes.append(p) or probe(p))
    src = tmp_path / "s.h5"
    shutil.copy(serial_reference, src)
    argv = ["figures", str(src), "--fix", "amplitude=2um", "--metric", "asymmetry_ratio",
            "--out", str(tmp_path / "figs")]  # fmt: skip
    assert main(argv) == 0
    assert (tmp_path / "figs" / "map_asymmetry_ratio.png").stat().st_size > 0
    assert probes == [src]  # twice before


def _alpha_study(tmp_path: Path, old: str, new: str) -> Path:
    """TINY over alpha 0.05 and 0.15 with its spectra recorded (and ``old`` made ``new``), run."""
    text = TINY.replace(
        "  diameter: {from: 12 mm, to: 15 mm, count: 3}\n  preload: [3 N, 6 N]\n",
        "  alpha: [0.05, 0.15]\n",
    ).replace(old, new)
    study = tmp_path / "alpha.yaml"
    study.write_text(text + "record_spectra: true\n")
    out = tmp_path / "alpha.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 0
    return out


def test_fig4_from_a_study_over_alpha(tmp_path: Path) -> None:
    out = _alpha_study(tmp_path, "amplitudes: [0.5 um, 2 um]", "amplitudes: [2 um]")
    data = read_study(out)
    sweep = alpha_sweep_from_study(data)
    assert list(sweep.alphas) == [0.05, 0.15]
    np.testing.assert_allclose(sweep.alpha_actual, [0.05, 0.15], rtol=0.02)
    assert sweep.magnitude["ltr"].shape == (2, data.spectrum_freq_Hz.size)
    assert np.all(np.isfinite(sweep.output_Hz["rtl"]))
    assert main(["figures", str(out), "--out", str(tmp_path / "f")]) == 0
    assert (tmp_path / "f" / "alpha_sweep.png").exists()


def test_a_study_over_alpha_at_two_amplitudes_draws_alpha_against_amplitude_and_fig4(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One parameter at two or more amplitudes (the paper's Fig. 4 case): the maps put the
    amplitude along y (before: "y: no other varied parameter to draw along y", exit 2, and no
    Fig. 4), and Fig. 4 is drawn at the largest amplitude."""
    import matplotlib.pyplot as plt

    out = _alpha_study(tmp_path, "error_estimate: true", "error_estimate: false")
    capsys.readouterr()
    figs = tmp_path / "f"
    captured: list[Any] = []
    real = phase_map

    def spy(*args: Any, **kwargs: Any) -> Any:
        captured.append(real(*args, **kwargs))
        return captured[-1]

    import analysis.study_maps as sm

    mp = pytest.MonkeyPatch()
    mp.setattr(sm, "phase_map", spy)
    try:
        assert main(["figures", str(out), "--out", str(figs)]) == 0
    finally:
        mp.undo()
    said = capsys.readouterr().out
    assert "maps at the largest drive amplitude" not in said
    assert (figs / "map_asymmetry_ratio.png").stat().st_size > 0
    assert (figs / "alpha_sweep.png").stat().st_size > 0
    pm = captured[0]
    assert (pm.x_name, pm.y_name) == ("alpha", "amplitude")
    np.testing.assert_allclose(pm.y, [0.5e-6, 2e-6])
    assert pm.values.shape == (2, 2) and np.all(np.isfinite(pm.values)) and not pm.fixed
    plt.close("all")


def test_the_ranking_keeps_only_cells_meeting_the_conditions(serial_reference: Path) -> None:
    from analysis.study_maps import parse_condition

    data = read_study(serial_reference)
    cut = float(np.median(data.metrics["transmission_rtl"]))
    rows = rank_designs(data, "asymmetry_ratio", top=50, where=[parse_condition(
        f"transmission_rtl>{cut!r}")])  # fmt: skip
    assert rows and all(r["transmission_rtl"] > cut for r in rows)
    assert len(rows) == int(np.sum(data.metrics["transmission_rtl"] > cut))
    with pytest.raises(ValueError, match="METRIC>VALUE"):
        parse_condition("transmission_rtl=3")


def test_the_shipped_studies_load_and_the_example_is_small() -> None:
    from protocols.study import cell_table, load_study, shipped_studies

    assert {"example", "diameter_preload"} <= set(shipped_studies())
    for name in shipped_studies():
        assert cell_table(load_study(name).study).n_cells > 0
    example = load_study("example").study
    assert cell_table(example).n_cells <= 100 and example.simulation.duration <= 10e-3


def _lhs_study(tmp_path: Path, samples: int, preload: str) -> Path:
    """TINY as a Latin hypercube of ``samples`` over diameter and ``preload`` (a range), run."""
    text = (
        TINY.replace("sampling: grid", f"sampling: {{latin_hypercube: {samples}, seed: 1}}")
        .replace("{from: 12 mm, to: 15 mm, count: 3}", "{from: 12 mm, to: 15 mm}")
        .replace("[3 N, 6 N]", preload)
        .replace("amplitudes: [0.5 um, 2 um]", "amplitudes: [2 um]")
        .replace("cells_per_task: 3", "cells_per_task: 40")
        .replace("error_estimate: true", "error_estimate: false")
    )
    study = tmp_path / "lhs.yaml"
    study.write_text(text)
    out = tmp_path / "lhs.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 0
    return out


def test_a_latin_hypercube_study_is_binned_on_its_map(tmp_path: Path) -> None:
    data = read_study(_lhs_study(tmp_path, 80, "{from: 3 N, to: 6 N}"))
    pm = phase_map(data, "transmission_ltr", "diameter", "preload", bins=4)
    assert pm.values.shape == (4, 4) and pm.cells == 80
    assert pm.x[0] > 12e-3 and pm.x[-1] < 15e-3  # bin centres
    d, f = data.parameters["diameter"], data.parameters["preload"]
    first = (d < 12.75e-3) & (f < 3.75)  # the lowest bin of each axis
    assert pm.values[0, 0] == pytest.approx(np.mean(data.metrics["transmission_ltr"][first]))
    with pytest.raises(ValueError, match="sampled, not a grid"):
        phase_map(data, "transmission_ltr", "diameter", "n_cylinders", fixed={"preload": 4.0})


def test_maps_are_drawn_at_the_largest_amplitude_unless_asked_to_reduce(
    serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """A mean over drive amplitudes mixes regimes: the output peak's mean of 4.39 kHz (0.5 um)
    and 7.45 kHz (2 um) was drawn as 5.9 kHz, a peak no run has. By default the maps are now
    at the largest amplitude; ``--reduce`` given reduces over amplitude too."""
    import analysis.study_maps

    seen: list[dict[str, float]] = []
    real = analysis.study_maps.phase_map

    def spy(*a: Any, **k: Any) -> Any:
        seen.append(dict(k["fixed"]))
        return real(*a, **k)

    monkeypatch.setattr(analysis.study_maps, "phase_map", spy)
    src = tmp_path / "s.h5"
    shutil.copy(serial_reference, src)
    argv = ["figures", str(src), "--metric", "peak_frequency_ltr", "--out", str(tmp_path / "f")]
    assert main(argv) == 0
    assert "maps at the largest drive amplitude, 2 um" in capsys.readouterr().out
    assert seen == [{"amplitude": 2e-6}]
    assert main([*argv, "--reduce", "mean"]) == 0
    assert "largest drive amplitude" not in capsys.readouterr().out and seen[-1] == {}


def test_a_small_latin_hypercube_is_binned_too_about_one_point_a_cell(tmp_path: Path) -> None:
    """40 samples (fewer than the 64 distinct values that made an axis a grid) were drawn as a
    40 x 40 map of slivers (a second reader)."""
    out = _lhs_study(tmp_path, 40, "{from: 1 N, to: 50 N, spacing: log}")
    pm = phase_map(read_study(out), "transmission_ltr", "diameter", "preload")
    assert pm.values.shape == (6, 6) and pm.cells == 40  # round(sqrt(40)) bins an axis
    assert pm.y_log and not pm.x_log  # 1-50 N drawn in log bins


def test_failed_cells_are_counted_and_crossed_not_called_off_accuracy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second reader: the map's title said "3 cells off accuracy left out" for cells that
    failed (no chain for that alpha), drawn as the cells not run, and the header said
    "12 of 12 cells run (complete)"."""
    text = TINY.replace("  preload: [3 N, 6 N]\n", "  alpha: [0.1, 1.9]\n")
    study = tmp_path / "af.yaml"
    study.write_text(text)
    out = tmp_path / "af.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 4
    data = read_study(out)
    assert int(np.sum(data.status == 3)) == 6  # alpha 1.9 at each diameter and amplitude
    # counted where the map is drawn (a reviewer: the title counted every amplitude's)
    pm = phase_map(data, "transmission_ltr", "diameter", "alpha", fixed={"amplitude": 2e-6})
    assert pm.failed == 3 and pm.left_out == 0
    assert sorted(y for _, y in pm.failed_xy) == [1.9] * 3
    capsys.readouterr()
    assert main(["figures", str(out), "--out", str(tmp_path / "f")]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert head.endswith("12 of 12 cells run (complete); 6 failed"), head


def test_the_ranking_is_at_the_maps_amplitude(
    serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The maps were at the largest amplitude and best_designs.txt ranked every amplitude:
    the example's top 7 were 0.5 um cells the maps did not show (a second reader)."""
    src = tmp_path / "s.h5"
    shutil.copy(serial_reference, src)
    assert main(["figures", str(src), "--out", str(tmp_path / "f")]) == 0
    table = (tmp_path / "f" / "best_designs.txt").read_text().splitlines()
    rows = [line for line in table if line.strip()[:1].isdigit()]
    assert rows and all(" 2 um " in line for line in rows), table
    assert table[-1].startswith("(at the largest drive amplitude")
    assert main(["figures", str(src), "--out", str(tmp_path / "g"), "--reduce", "mean"]) == 0
    mixed = (tmp_path / "g" / "best_designs.txt").read_text()
    assert " 0.5 um " in mixed and "largest drive amplitude" not in mixed


def test_fig4_keeps_an_alpha_whose_first_direction_has_no_peak(tmp_path: Path) -> None:
    """A reviewer: an alpha whose LTR peak is not given (none inside the search range) was
    dropped from Fig. 4 whole, its spectra and its RTL peak with it."""
    data = read_study(_alpha_study(tmp_path, "amplitudes: [0.5 um, 2 um]", "amplitudes: [2 um]"))
    at = data.parameters["alpha"] == 0.15
    data.metrics["peak_frequency_ltr"][at] = np.nan
    sweep = alpha_sweep_from_study(data)
    assert list(sweep.alphas) == [0.05, 0.15]
    assert np.isnan(sweep.output_Hz["ltr"][1]) and np.isfinite(sweep.output_Hz["rtl"][1])
