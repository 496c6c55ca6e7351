"""``biafc compare``: the model on what a run did, residuals, marked points, figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from printed_lines import PrintedLines

from analysis.compare import point_states
from analysis.compare_report import compare_run
from analysis.model_run import run_setup
from analysis.synthetic_scan import write_synthetic_scan
from daq.cli.biafc import main as biafc
from instruments.burst import Burst
from protocols.runfile import PointState, read_run
from sim_backend.dem import default_chain_spec

CYL = (1, 9, 16, 23, 31)


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small scan of the default chain (what the file says), one point failed."""
    path = tmp_path_factory.mktemp("cmp") / "scan.h5"
    return write_synthetic_scan(
        path,
        true_spec=default_chain_spec(),
        amplitudes_m=(20e-9, 2e-6),
        cylinders=CYL,
        duration_s=8e-3,
        failed=[("ltr", 1, 2)],
    )


def test_setup_reads_drive_through_bench_gain_and_stroke(scan: Path) -> None:
    run = read_run(scan)
    s = run_setup(run)
    assert s.amplifier_gain_V_per_V == 20.0 and s.bench_stroke_m_per_V == pytest.approx(5e-8)
    assert np.allclose(s.directions["ltr"].drive_SI, [20e-9, 2e-6])
    assert s.clip_m_per_s == pytest.approx(0.5)  # 50 mm/s/V x 10 V
    fitted = run_setup(run, piezo_stroke_m_per_V=4e-8)
    assert np.allclose(fitted.directions["rtl"].drive_SI, [16e-9, 1.6e-6])
    assert s.directions["ltr"].burst.f_center_Hz == 8920.0
    assert list(s.directions["ltr"].cylinders) == list(CYL)


def test_generator_volts_reach_the_chain_through_gain_and_stroke(scan: Path) -> None:
    run = read_run(scan)
    run.scans["ltr"].amplitude_units = "V"
    run.scans["ltr"].amplitudes = np.array([0.04, 4.0])  # Vpp at the generator
    s = run_setup(run)
    # 0.5 * Vpp * 20 V/V * 0.05 um/V
    assert np.allclose(s.directions["ltr"].drive_SI, [20e-9, 2e-6])


def test_true_model_sits_at_the_noise_floor_and_a_wrong_one_does_not(scan: Path) -> None:
    run = read_run(scan)
    good = compare_run(run, None).comparison
    assert good.counts == {"ok": 19, "pending": 0, "failed": 1, "clipped": 0}
    assert good.directions["ltr"].state[1, 2] == "failed"
    assert np.isnan(good.directions["ltr"].spectral_residual[1, 2])
    # the true model: its residual is what the noise and the trigger jitter explain
    assert good.figure_of_merit < 0.15
    assert good.time_figure < 1.5 * good.noise_figure + 0.05
    wrong = default_chain_spec().model_copy(update={"diameter": 14.4e-3})
    bad = compare_run(run, None, chain_spec=wrong).comparison
    assert bad.figure_of_merit > 3 * good.figure_of_merit
    too_strong = compare_run(run, None, piezo_stroke_m_per_V=7e-8).comparison
    assert too_strong.figure_of_merit > 2 * good.figure_of_merit


def test_clipped_and_failed_points_are_marked_not_compared() -> None:
    done = np.array([[PointState.DONE, PointState.FAILED, PointState.DONE, PointState.PENDING]])
    v = np.zeros((1, 4, 16))
    v[0, 2, 5] = 0.4999  # reaches the clip level
    v[0, 3] = np.nan
    assert list(point_states(done, v, 0.5)[0]) == ["ok", "failed", "clipped", "pending"]
    assert list(point_states(done, v, np.inf)[0]) == ["ok", "failed", "ok", "pending"]


def test_cli_writes_side_by_side_figures_and_table(
    scan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    assert biafc(["compare", str(scan), "--out", str(out), "--linear"]) == 0
    text = capsys.readouterr().out
    assert "figure of merit" in text and "1 failed" in text
    for name in ("compare_spatial_ltr_low", "compare_spatial_rtl_high", "compare_spectra_ltr",
                 "compare_sweep", "compare_residuals"):  # fmt: skip
        assert (out / f"{name}.png").stat().st_size > 10_000
    summary = json.loads((out / "comparison.json").read_text())
    assert summary["points"]["failed"] == 1
    assert len(summary["cylinders"]) == len(CYL)
    rows = (out / "residuals.csv").read_text().splitlines()
    assert rows[0].startswith("cylinder,points,spectral_residual") and len(rows) == 1 + len(CYL)


def test_cli_prints_the_table_first_and_each_figure_as_it_is_saved(
    scan: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Everything was printed at the end: 5.8 s of silence on a biafc_sweep run (the figures
    5.5 of 7.5 s), then the table and every "written" line at once. Now the table and the
    figure of merit come before any figure is drawn (2.5 s), each "written" line once its files
    are saved."""
    out = tmp_path / "cmp"
    rec = PrintedLines(out)
    monkeypatch.setattr("sys.stdout", rec)
    assert biafc(["compare", str(scan), "--out", str(out), "--linear"]) == 0
    lines = [line for line, _ in rec.lines]
    seen = dict(rec.lines)
    merit = next(line for line in lines if line.startswith("figure of merit"))
    assert seen[lines[0]] == set() and seen[merit] == set()  # before any figure
    written = [line for line in lines if line.startswith("written ") and ".png" in line]
    assert len(written) == 8  # 3 per direction, the sweep, the residuals
    assert lines.index(merit) < lines.index(written[0])
    for i, line in enumerate(written):  # each once its own file is there, before the next's
        name = line.split(":")[0].removeprefix("written ")
        assert name in seen[line] and len(seen[line]) == i + 1
    assert lines[-2:] == [f"written {out / 'residuals.csv'}", f"written {out / 'comparison.json'}"]


def test_cli_refuses_a_bad_chain_file_in_one_line(
    scan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("diameter: -3 mm\nn_cylinders: 31\nlength_first: 90 mm\nlength_last: 110 mm\n")
    assert biafc(["compare", str(scan), "--chain", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "diameter" in err and len(err.splitlines()) == 1
    assert biafc(["compare", str(scan), "--piezo-stroke", "0.04 um"]) == 2
    assert "per volt" in capsys.readouterr().err


def test_the_band_edges_are_the_modelled_chains_and_an_incomplete_run_is_said(
    scan: Path,
) -> None:
    """With ``--chain`` the figures drew the run file's chain's band edges beside the other
    chain's prediction (cylinder 1's onset 8.27 kHz for 8.10), and an aborted run was compared
    without a word of it."""
    import dataclasses

    from sim_backend.dem import build_chain, quasi_bands

    run = read_run(scan)
    wrong = default_chain_spec().model_copy(update={"diameter": 14.4e-3})
    report = compare_run(run, None, chain_spec=wrong)
    bands = quasi_bands(build_chain(wrong), np.atleast_2d(run.chain.onset_Hz).shape[1])
    assert np.allclose(report.predicted.chain.onset_Hz, bands.onset_Hz)
    assert not np.allclose(report.predicted.chain.onset_Hz, run.chain.onset_Hz)
    assert "the run file is" not in report.text() and "solver dem" in report.text()
    aborted = dataclasses.replace(run, attrs={**run.attrs, "status": "aborted"})
    assert "the run file is aborted" in compare_run(aborted, None).text()


def test_the_figures_say_what_they_scale_to_and_draw_one_amplitudes_model(scan: Path) -> None:
    """Nothing measured: the map was labelled "dB re measured max" while scaled to the model's;
    one amplitude: the model's sweep was a line through one point, drawn as nothing."""
    import matplotlib

    matplotlib.use("Agg")
    from analysis.plots.compare_plot import plot_compare_spatial, plot_compare_sweep
    from analysis.spatial import SpatialFrequencyMap

    cyl = np.array([1, 2, 3], dtype=np.int32)
    f = np.linspace(1e3, 2e4, 50)
    empty = SpatialFrequencyMap(cyl, f, np.full((3, 50), np.nan), np.full(3, np.nan))
    model = SpatialFrequencyMap(cyl, f, np.ones((3, 50)), np.full(3, 9e3))
    fig = plot_compare_spatial(empty, model, np.array(["pending"] * 3), f[:3], f[3:6], 9e3, "x")
    assert any("dB re model max" in ax.get_ylabel() for ax in fig.axes)
    one = write_synthetic_scan(
        scan.with_name("one.h5"),
        true_spec=default_chain_spec(),
        amplitudes_m=(2e-6,),
        cylinders=CYL,
        duration_s=8e-3,
    )
    cmp = compare_run(read_run(one), None).comparison
    lines = [ln for ax in plot_compare_sweep(cmp).axes for ln in ax.get_lines()]
    model = [ln for ln in lines if str(ln.get_label()).endswith("model")]
    assert model and all(ln.get_marker() not in ("None", "", None) for ln in model)
    # one amplitude's far-end spectra: the title fits the figure (it was cut at both ends)
    from analysis.plots.compare_plot import plot_compare_spectra

    fig = plot_compare_spectra(cmp.directions["ltr"])
    fig.canvas.draw()
    title = fig._suptitle.get_window_extent()  # type: ignore[union-attr]
    assert title.x0 >= 0 and title.x1 <= fig.bbox.x1


def test_a_far_cylinder_outside_the_protocol_is_unscanned_and_not_drawn(
    tmp_path: Path,
) -> None:
    """Before, a run whose protocol stops short of the far cylinder (smoke: 1, 8, 16) drew
    empty spectra panels titled '(pending)', a sweep of nothing, and legend entries 'pending'
    for a cylinder no point had been planned on."""
    path = write_synthetic_scan(
        tmp_path / "short.h5",
        true_spec=default_chain_spec(),
        amplitudes_m=(20e-9, 2e-6),
        cylinders=(1, 8, 16),
        duration_s=8e-3,
    )
    report = compare_run(read_run(path), tmp_path / "out")
    dc = report.comparison.directions["ltr"]
    assert list(dc.state_of(31)) == ["unscanned", "unscanned"]
    assert list(dc.state_of(1)) == ["ok", "ok"]
    assert not dc.far_scanned() and not dc.sweep_scanned()
    assert "compare_spectra_ltr" not in report.files and "compare_sweep" not in report.files
    assert "#31 is not in the run's protocol" in report.not_drawn["compare_spectra_ltr"]
    assert "compare_residuals" in report.files  # what can be compared still is


def test_the_prediction_reaches_the_records_last_sample() -> None:
    """The models sample [0, duration]; run for exactly a record's last time, at a rate read
    from its time axis (499999.99999993 S/s for a 30 ms ``biafc simulate`` file), they stopped
    a sample short, and the prediction's last value read 0 (a time-domain residual of 0.002
    for a file compared with its own model)."""
    from analysis.model_run import _on_time_axis, model_duration_s
    from sim_backend.dem import Drive, build_chain
    from sim_backend.dem.linear_response import linear_response

    t = np.linspace(0.0, 0.03, 15001)  # as a simulate file's axis: 0 to 30 ms at 500 kS/s
    rate = 1.0 / float(np.median(np.diff(t)))
    drive = Drive("ltr", "displacement", 1e-8, Burst(8920.0))
    lr = linear_response(
        build_chain(default_chain_spec()),
        [drive],
        duration_s=model_duration_s(float(t[-1]), rate),
        sample_rate_Hz=rate,
        cylinders=[1],
        record=("velocity",),
    )
    assert lr.velocity is not None and lr.time_s.size == t.size
    v = _on_time_axis(lr.time_s, lr.velocity[0, 0], t)
    assert v[-1] != 0.0 and abs(v[-1]) > 1e-3 * np.abs(v).max()


def test_a_piezo_stroke_for_a_file_without_a_bench_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A biafc simulate file holds the drive itself: --piezo-stroke was silently ignored (exit
    0, a residual of 0.000 that never used it)."""
    sim = tmp_path / "sim.h5"
    args = ["simulate", "--direction", "ltr", "--amplitude", "1um", "--duration", "5ms"]
    assert biafc([*args, "--rate", "200kS/s", "--out", str(sim)]) == 0
    capsys.readouterr()
    out = tmp_path / "cmp"
    assert biafc(["compare", str(sim), "--piezo-stroke", "0.04um/V", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no bench in the file" in err and "drop --piezo-stroke" in err
    assert len(err.splitlines()) == 1 and not out.exists()


def test_points_a_figure_cannot_draw_are_crosses_not_gaps(scan: Path) -> None:
    """A second reader's run with failed points: the residual figure did not mark them at all,
    and the regime figure left a failed amplitude out without a mark."""
    import dataclasses

    import matplotlib.pyplot as plt

    from analysis.plots.compare_plot import plot_compare_residuals
    from analysis.plots.regime_plot import plot_regime
    from analysis.sweep import amplitude_sweep

    run = read_run(scan)
    fig = plot_compare_residuals(compare_run(run, None).comparison)
    marks = [ln for ln in fig.axes[0].lines if ln.get_label().startswith("has failed points")]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [16]  # ltr, 2 um, cylinder 16
    plt.close(fig)
    sw = amplitude_sweep(run.scans["ltr"], run.chain)
    lost = sw.transmission.copy()
    lost[1] = np.nan  # the entry or the far point of 2 um failed
    fig = plot_regime({"ltr": dataclasses.replace(sw, transmission=lost)})
    crosses = [ln for ln in fig.axes[0].lines if ln.get_label() == "LTR failed or not measured"]
    assert len(crosses) == 1 and np.allclose(crosses[0].get_xdata(), [2.0])  # um
    plt.close(fig)


def test_a_conversion_whose_entry_point_failed_says_failed_not_unmeasured(scan: Path) -> None:
    import dataclasses

    from analysis.summary import summary_rows
    from analysis.sweep import amplitude_sweep

    run = read_run(scan)
    s = run.scans["ltr"]
    done, velocity = s.done.copy(), s.velocity.copy()
    done[1, 0], velocity[1, 0] = PointState.FAILED, np.nan  # 2 um at cylinder 1, the entry
    failed = dataclasses.replace(s, done=done, velocity=velocity)
    rows = summary_rows(amplitude_sweep(failed, run.chain), failed)
    assert rows[1]["conversion"] == "failed: entry point"  # it read "not measured"
    assert rows[0]["conversion"] != "failed: entry point"


def test_the_high_amplitude_map_is_the_highest_measured(
    scan: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """In an aborted run the protocol's largest amplitude may never have been measured: its
    'high' map was all hatched while a lower amplitude had its cylinders."""
    import shutil

    import h5py

    import analysis.plots.compare_plot as cp

    part = tmp_path / "part.h5"
    shutil.copy(scan, part)
    with h5py.File(part, "r+") as f:
        for d in ("ltr", "rtl"):
            f["scan"][d]["done"][1, :] = PointState.PENDING  # 2 um never measured
    titles: list[str] = []
    real = cp.plot_compare_spatial

    def keep(*a, **k):  # type: ignore[no-untyped-def]
        titles.append(a[-1])
        return real(*a, **k)

    monkeypatch.setattr(cp, "plot_compare_spatial", keep)
    compare_run(read_run(part), tmp_path / "cmp")
    assert titles and all("20 nm" in t for t in titles), titles


def test_far_records_at_the_noise_floor_are_bounds_not_compared(tmp_path: Path) -> None:
    """A simulated ``biafc_sweep`` run compared with its own chain drew the far end's noise as
    measured (E_far/E_entry 1.2e-2 at 10 nm against the model's 8e-5), and its figure of merit
    (0.220) counted those noise records and had no noise reference to read it against."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.plots.compare_plot import plot_compare_sweep

    scan = write_synthetic_scan(  # 2 nm: the far ends hold only the noise
        tmp_path / "noisy.h5",
        true_spec=default_chain_spec(),
        amplitudes_m=(2e-9, 2e-6),
        cylinders=CYL,
        duration_s=8e-3,
        noise_m_per_s=1e-5,
    )
    report = compare_run(read_run(scan), tmp_path / "cmp")
    cmp = report.comparison
    n_floor = 0
    kept: list[float] = []
    for dc in cmp.directions.values():
        ms = dc.measured_sweep
        far = list(dc.cylinders).index(ms.far)
        assert ms.at_noise_floor[0] and not ms.at_noise_floor[-1]  # 2 nm: noise; 2 um: not
        assert list(dc.at_noise_floor[:, far]) == list(ms.at_noise_floor)
        assert not np.delete(dc.at_noise_floor, far, axis=1).any()
        n_floor += int(ms.at_noise_floor.sum())
        kept += list(dc.spectral_residual[(dc.state == "ok") & ~dc.at_noise_floor])
        # the model's far end set like against like: within the signal band, as measured
        assert np.all(dc.predicted_signal[ms.at_noise_floor] <= ms.transmission_bound[0])
    assert cmp.n_noise_floor == n_floor == 2
    assert int(cmp.n_points.sum()) == cmp.counts["ok"] - n_floor
    assert cmp.figure_of_merit == pytest.approx(np.sqrt(np.mean(np.square(kept))))
    # the true model: its figure of merit is what the noise alone gives
    assert 0.0 < cmp.spectral_noise_figure
    assert cmp.figure_of_merit < 1.5 * cmp.spectral_noise_figure + 0.02
    text = report.text()
    assert f"{n_floor} far records at the noise floor" in text and "noise alone" in text
    summary = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    assert summary["far_records_at_noise_floor"] == n_floor
    assert summary["figure_of_merit_noise_floor"] == pytest.approx(cmp.spectral_noise_figure)
    fig = plot_compare_sweep(cmp)
    ax_t = fig.axes[0]
    for d, dc in cmp.directions.items():
        ms = dc.measured_sweep
        bounds = [
            ln for ln in ax_t.lines if ln.get_label() == f"{d.upper()} at the noise floor (at most)"
        ]
        assert len(bounds) == 1 and bounds[0].get_marker() == "v"
        assert np.allclose(bounds[0].get_ydata(), ms.transmission_bound[ms.at_noise_floor])
        (meas,) = [ln for ln in ax_t.lines if ln.get_label() == f"{d.upper()} measured"]
        assert np.size(meas.get_xdata()) == int(
            (~ms.at_noise_floor & (dc.sweep_state() == "ok")).sum()
        )
    plt.close(fig)


def test_the_far_end_peaks_say_whether_they_converted(scan: Path) -> None:
    """The far-end peak panel drew every peak, measured and model, as the same filled dot:
    a 20 nm line that had not converted could not be told from a 2 um conversion. It speaks
    the regime figure's language now (the summary's verdict): filled where converted, hollow
    grey where not, and its legend names the styles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import same_color

    from analysis.plots.compare_plot import plot_compare_sweep
    from analysis.plots.quasi_bands import DIRECTION_COLOURS
    from analysis.summary import summary_rows

    cmp = compare_run(read_run(scan), None).comparison
    fig = plot_compare_sweep(cmp)
    ax_f = fig.axes[1]
    named = {str(ln.get_label()): ln for ln in ax_f.lines}
    legend = [t.get_text() for t in ax_f.get_legend().get_texts()]
    for d, dc in cmp.directions.items():
        colour = DIRECTION_COLOURS[d]
        for series, sw in (("measured", dc.measured_sweep), ("model", dc.predicted_sweep)):
            # the summary's verdicts: 20 nm passes nothing, 2 um converts
            verdicts = [r["conversion"] for r in summary_rows(sw)]
            assert verdicts[0] == "none" and verdicts[1] in ("down", "up"), (d, series)
            full = named[f"{d.upper()} {series}, converted"]
            hollow = named[f"{d.upper()} {series}, not converted"]
            assert np.allclose(full.get_xdata(), [2.0]) and np.allclose(hollow.get_xdata(), [0.02])
            assert np.allclose(full.get_ydata(), sw.output_Hz[1:] / 1e3)  # the same numbers
            assert np.allclose(hollow.get_ydata(), sw.output_Hz[:1] / 1e3)
            assert same_color(full.get_markerfacecolor(), colour)
            assert hollow.get_markerfacecolor() == "none"
            assert same_color(hollow.get_markeredgecolor(), "grey")
            assert {f"{d.upper()} {series}, converted", str(hollow.get_label())} <= set(legend)
    plt.close(fig)
