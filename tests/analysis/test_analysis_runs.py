"""Figures and summary from whole run files: complete, partial, and through the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import analysis_synthetic as synthetic
import numpy as np
import pytest
from printed_lines import PrintedLines

from analysis.bands import band_edges
from analysis.report import measured_amplitudes, stft_cylinders, write_figures
from analysis.spatial import spatial_frequency_map
from analysis.spatiotemporal import (
    arrival_time_s,
    energy_beyond_fraction,
    penetration_cylinder,
    spatiotemporal_map,
)
from analysis.summary import conversion_verdict, summarize
from analysis.sweep import amplitude_sweep, transmission_gain
from daq.cli.biafc import main as biafc_main
from protocols.runfile import read_run

EXPECTED_FIGURES = {
    "quasi_bands",
    "amplitude_sweep",
    "regime",
    *(
        f"{k}_{d}"
        for k in ("spectra", "spatial_frequency", "stft", "spatiotemporal")
        for d in ("ltr", "rtl")
    ),
}


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synthetic.write_run(tmp_path_factory.mktemp("full") / "run.h5")


@pytest.fixture(scope="module")
def partial_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # amplitude 3 never measured; at amplitude 2 only cylinders 1..10 measured (a run aborted
    # mid-scan); RTL amplitude 0 misses every other cylinder
    def skip(d: str, a: int, c: int) -> bool:
        if a == 3:
            return True
        if a == 2:
            return c >= 10
        return d == "rtl" and a == 0 and c % 2 == 1

    return synthetic.write_run(
        tmp_path_factory.mktemp("partial") / "run.h5", partial=skip, status="aborted"
    )


def test_sweep_reads_down_and_up_conversion(full_run: Path) -> None:
    run = read_run(full_run)
    ltr = amplitude_sweep(run.scans["ltr"], run.chain)
    rtl = amplitude_sweep(run.scans["rtl"], run.chain)
    assert ltr.far == 31 and rtl.far == 1
    assert np.allclose(ltr.input_Hz, synthetic.F_LTR_HZ, atol=20)
    assert np.allclose(rtl.input_Hz, synthetic.F_RTL_HZ, atol=20)
    # converting amplitudes (>= 2 um): output at the far cylinder's edge
    assert np.allclose(ltr.output_Hz[2:], 8010.0, atol=30)
    assert np.allclose(rtl.output_Hz[2:], 8080.0, atol=30)
    assert ltr.expected_Hz == pytest.approx(8010.0) and rtl.expected_Hz == pytest.approx(8080.0)
    assert np.all(ltr.detuning_Hz[2:] < -800) and np.all(rtl.detuning_Hz[2:] > 1300)
    assert np.all(ltr.transmission[:2] < 1e-6) and np.all(ltr.transmission[2:] > 0.1)


def test_summary_verdicts(full_run: Path) -> None:
    summary = summarize(read_run(full_run))
    verdict = {(r["direction"], r["amplitude"]): r["conversion"] for r in summary["rows"]}
    assert verdict[("ltr", 4e-6)] == "down" and verdict[("rtl", 4e-6)] == "up"
    assert verdict[("ltr", 0.5e-6)] == "none" and verdict[("rtl", 0.5e-6)] == "none"
    assert summary["far_cylinder"] == {"ltr": 31, "rtl": 1}
    json.dumps(summary, allow_nan=False)  # JSON-clean: no NaN


def test_conversion_verdict_rules() -> None:
    # with a linear reference: the gain decides whether energy got through
    assert conversion_verdict(-900.0, 8920.0, 1e-3, gain=60.0) == "down"
    assert conversion_verdict(900.0, 6630.0, 1e-3, gain=60.0) == "up"
    assert conversion_verdict(-900.0, 8920.0, 0.2, gain=1.0) == "none"  # a linear leak
    assert conversion_verdict(-10.0, 8920.0, 0.2, gain=60.0) == "none"  # passes, unconverted
    # without one (a single amplitude): the transmission level decides
    assert conversion_verdict(-900.0, 8920.0, 0.2) == "down"
    assert conversion_verdict(-900.0, 8920.0, 1e-3) == "none"
    assert conversion_verdict(float("nan"), 8920.0, float("nan")) == "not measured"


def test_transmission_gain_reference_is_the_smallest_amplitude() -> None:
    g = transmission_gain(np.array([4.0, 1.0, 2.0, 8.0]), np.array([0.4, 0.01, np.nan, 0.8]))
    assert np.allclose(g[[0, 1, 3]], [40.0, 1.0, 80.0]) and np.isnan(g[2])
    assert np.all(np.isnan(transmission_gain(np.array([1.0, 2.0]), np.array([0.1, np.nan]))))


def test_spatial_map_tracks_the_sliding_frequency(full_run: Path) -> None:
    scan = read_run(full_run).scans["ltr"]
    m = spatial_frequency_map(scan.velocity[3], scan.cylinders, scan.sample_rate_Hz, (4e3, 13e3))
    assert m.magnitude.shape == (31, m.freq_Hz.size)
    expected = 8920.0 + (8010.0 - 8920.0) * np.arange(31) / 30
    assert np.max(np.abs(m.peak_Hz - expected)) < 40


def test_spatiotemporal_penetration_and_arrival(full_run: Path) -> None:
    run = read_run(full_run)
    scan = run.scans["ltr"]
    rate = scan.sample_rate_Hz
    # low amplitude: velocity gain 10**(-0.2 (i - 11)) past the 12th cylinder from the entry,
    # so the energy is within -20 dB up to i = 15 (-16 dB) and at -20 dB at i = 16: #16
    low = penetration_cylinder(scan.velocity[0], scan.cylinders, "ltr", rate)
    assert low == 16
    assert penetration_cylinder(scan.velocity[3], scan.cylinders, "ltr", rate) >= 30
    rtl = run.scans["rtl"]
    low_r = penetration_cylinder(rtl.velocity[0], rtl.cylinders, "rtl", rate)
    assert low_r == 31 - 15  # the same depth from the other end
    arr = arrival_time_s(scan.velocity[3], scan.time_s)
    assert np.allclose(np.diff(arr), synthetic.HOP_S, atol=2 / rate)
    st = spatiotemporal_map(scan.velocity[3], scan.cylinders, scan.time_s)
    assert st.envelope.shape == scan.velocity[3].shape


def test_every_figure_written_from_a_complete_run(full_run: Path, tmp_path: Path) -> None:
    report = write_figures(read_run(full_run), tmp_path)
    assert set(report.figures) == EXPECTED_FIGURES
    for paths in report.figures.values():
        assert {p.suffix for p in paths} == {".png", ".pdf"}
        assert all(p.stat().st_size > 5000 for p in paths)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert len(data["rows"]) == 8
    assert "down" in report.summary_text and "up" in report.summary_text


def test_partial_run_draws_what_is_done_and_leaves_gaps(partial_run: Path, tmp_path: Path) -> None:
    run = read_run(partial_run)
    assert run.status == "aborted"
    scan = run.scans["ltr"]
    assert measured_amplitudes(scan) == [0, 1, 2]
    report = write_figures(run, tmp_path)
    assert set(report.figures) == EXPECTED_FIGURES
    rows = {(r["direction"], r["amplitude"]): r for r in report.summary["rows"]}
    # amplitude 3 never measured, amplitude 2 misses the far cylinder #31: not measured
    assert rows[("ltr", 4e-6)]["conversion"] == "not measured"
    assert rows[("ltr", 2e-6)]["conversion"] == "not measured"
    assert rows[("ltr", 2e-6)]["output_Hz"] is None
    assert rows[("ltr", 1e-6)]["conversion"] == "none"
    # RTL amplitude 2: cylinders 1..10 include the far cylinder #1 but not the entry #31
    assert rows[("rtl", 2e-6)]["transmission"] is None
    # the spatial map of the highest measured amplitude has NaN rows where not measured
    m = spatial_frequency_map(scan.velocity[2], scan.cylinders, scan.sample_rate_Hz, (4e3, 13e3))
    assert np.all(np.isnan(m.magnitude[10:])) and np.all(np.isfinite(m.magnitude[:10]))
    assert np.all(np.isnan(m.peak_Hz[10:]))
    # the points' counts are said (before: nothing said how many were failed or missing, and
    # the figures' hatch called failed points "not measured")
    n_ltr = 4 * 31
    assert report.summary["points"]["ltr"] == {"measured": 3 * 31 - 21, "failed": 0,
                                               "pending": 31 + 21}  # fmt: skip
    assert f"points ltr: {3 * 31 - 21} measured, 0 failed, {31 + 21} not measured" in (
        report.summary_text
    )
    assert sum(report.summary["points"]["ltr"].values()) == n_ltr
    from analysis.plots.style import GAP_LABEL

    assert GAP_LABEL == "failed or not measured"


def test_partial_gaps_are_masked_in_the_drawn_map(partial_run: Path) -> None:
    from analysis.plots.spatial_plot import plot_spatial_frequency

    run = read_run(partial_run)
    scan = run.scans["rtl"]
    m = spatial_frequency_map(scan.velocity[0], scan.cylinders, scan.sample_rate_Hz, (4e3, 13e3))
    onset, cutoff = band_edges(run.chain)
    fig = plot_spatial_frequency(m, "rtl", scan.f_center_Hz, onset, cutoff, far=1)
    mesh = fig.axes[0].collections[0]
    arr = np.ma.masked_invalid(mesh.get_array()).reshape(m.freq_Hz.size, 31)
    # every other cylinder (even 0-based index 1, 3, ...) not measured: masked columns
    assert np.all(arr.mask[:, 1::2]) and not np.any(arr.mask[:, 0::2])
    hatched = [p for p in fig.axes[0].patches if p.get_hatch()]
    assert hatched, "the gap background is drawn"


def test_stft_cylinders_run_from_entry_to_far() -> None:
    assert stft_cylinders("ltr", 31) == [1, 7, 13, 19, 25, 31]
    assert stft_cylinders("rtl", 31) == [31, 25, 19, 13, 7, 1]


def test_cli_writes_figures_and_summary(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    run = synthetic.write_run(tmp_path / "ltr.h5", directions=("ltr",), amplitudes=(1e-6, 4e-6))
    assert biafc_main(["figures", str(run)]) == 0  # default folder: beside the run file
    out = tmp_path / "ltr_figures"
    printed = capsys.readouterr().out
    assert "down" in printed and "summary.json" in printed
    assert (out / "amplitude_sweep.png").exists() and (out / "quasi_bands.pdf").exists()
    assert not (out / "stft_rtl.png").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["figures"], "give a run file"),
        (["figures", "missing.h5"], "does not exist"),
        (["figures", "X.h5", "--alpha-sweep"], "not both"),
        (["figures", "X.h5", "--alphas", "0.1"], "--alphas applies only"),
        (["figures", "--alpha-sweep", "--amplitude", "3kHz"], "--amplitude"),
        (["figures", "--alpha-sweep", "--alphas", "0.1,x"], "--alphas"),
        (["figures", "--alpha-sweep", "--alphas", "-0.1"], "--alphas"),
        (["figures", "--alpha-sweep", "--duration", "8"], "--duration"),
        (["figures", "--alpha-sweep", "--cycles", "0"], "--cycles"),
        (["figures", "--alpha-sweep", "--linear-reference", "3kHz"], "--linear-reference"),
        (["figures", "X.h5", "--linear-reference", "10nm"], "--linear-reference applies only"),
    ],
)
def test_cli_user_errors_are_one_line(argv: list[str], message: str, capsys) -> None:  # type: ignore[no-untyped-def]
    assert biafc_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_cli_refuses_a_file_that_is_not_a_run(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not hdf5 at all")
    assert biafc_main(["figures", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.h5" in err and "\n" not in err


def test_energy_beyond_fraction_counts_from_the_entry() -> None:
    v = np.stack([np.full(10, a) for a in (1.0, 1.0, 2.0, 0.0)])  # energies 1, 1, 4, 0 (x 10/rate)
    cyl = np.array([1, 2, 3, 4])
    assert energy_beyond_fraction(v, cyl, "ltr", 3, 1.0) == pytest.approx(4 / 6)
    assert energy_beyond_fraction(v, cyl, "rtl", 2, 1.0) == pytest.approx(2 / 6)
    v[2] = np.nan  # unmeasured cylinders are left out of both sums
    assert energy_beyond_fraction(v, cyl, "ltr", 2, 1.0) == pytest.approx(1 / 2)


def test_one_short_point_gives_what_it_can(tmp_path: Path) -> None:
    """A run aborted after its first point, with records shorter than one STFT frame."""
    from protocols.runfile import RunFileWriter, ScanSpec

    t = np.arange(100) / 200e3
    spec = ScanSpec("ltr", np.array([1.0]), "V", np.arange(1, 32, dtype=np.int32), t, 8920.0)
    w = RunFileWriter.create(tmp_path / "short.h5", backend="sim", chain=synthetic.chain(),
                             scans=[spec])  # fmt: skip
    tone = np.sin(2 * np.pi * 8920 * t)
    w.write_point("ltr", 0, 0, tone, tone)
    w.close("aborted")
    report = write_figures(read_run(tmp_path / "short.h5"), tmp_path / "figs")
    assert {"quasi_bands", "spectra_ltr", "spatial_frequency_ltr"} <= set(report.figures)
    assert set(report.skipped) == {"stft_ltr", "amplitude_sweep", "regime"}
    assert report.summary["rows"][0]["conversion"] == "not measured"


def test_one_amplitude_leaves_out_the_sweep_and_says_why(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    """An amplitude sweep with one amplitude is degenerate: left out, the reason in the summary
    (printed and in summary.json)."""
    import json

    run = synthetic.write_run(tmp_path / "one.h5", directions=("ltr",), amplitudes=(4e-6,))
    assert biafc_main(["figures", str(run), "--out", str(tmp_path / "f")]) == 0
    printed = capsys.readouterr().out
    assert not (tmp_path / "f" / "amplitude_sweep.png").exists()
    assert (tmp_path / "f" / "spectra_ltr.png").exists()
    why = "far cylinder 31 measured at 1 amplitude(s); a sweep needs 2"
    assert f"left out amplitude_sweep: ltr: {why}" in printed
    summary = json.loads((tmp_path / "f" / "summary.json").read_text())
    assert why in summary["figures_left_out"]["amplitude_sweep"]


def test_a_direction_with_one_amplitude_is_left_out_of_the_sweep(tmp_path: Path) -> None:
    run = synthetic.write_run(
        tmp_path / "two.h5", directions=("ltr", "rtl"), amplitudes=(1e-6, 4e-6)
    )
    data = read_run(run)
    data.scans["rtl"].done[1:] = 0  # rtl measured at its first amplitude only
    data.scans["rtl"].velocity[1:] = np.nan
    report = write_figures(data, tmp_path / "figs")
    assert "amplitude_sweep" in report.figures
    assert "rtl" in report.skipped["amplitude_sweep (rtl)"]


def test_a_far_cylinder_outside_the_scan_is_named_not_called_unmeasured(tmp_path: Path) -> None:
    """smoke.yaml scans cylinders 1, 8 and 16: every point measured, and the summary said
    "not measured" for each amplitude (a second reader)."""
    from daq.cli.run_protocol import main as run_protocol

    out = tmp_path / "smoke.h5"
    assert run_protocol(["smoke.yaml", "--out", str(out), "-q"]) == 0
    rows = summarize(read_run(out))["rows"]
    assert [r["conversion"] for r in rows] == ["not scanned: far cylinder 31"] * 2


def test_figures_print_the_summary_first_and_each_figure_as_it_is_saved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Everything was printed at the end: 5.1 s of silence on a biafc_sweep run, then the
    summary and every "written" line at once. Now the summary comes before any figure is drawn
    (0.8 s), each "written" line once its files are saved, the "left out" lines at the end."""
    run = synthetic.write_run(tmp_path / "one.h5", directions=("ltr",), amplitudes=(4e-6,))
    out = tmp_path / "f"
    rec = PrintedLines(out)
    monkeypatch.setattr("sys.stdout", rec)
    assert biafc_main(["figures", str(run), "--out", str(out)]) == 0
    lines = [line for line, _ in rec.lines]
    seen = dict(rec.lines)
    assert lines[0].startswith(f"{run}  status=")
    assert seen[lines[0]] == set()  # the summary: before any figure
    written = [line for line in lines if line.startswith("written ") and ".png" in line]
    assert [w.split(":")[0] for w in written] == [
        "written quasi_bands", "written spectra_ltr", "written spatial_frequency_ltr",
        "written stft_ltr", "written spatiotemporal_ltr",
    ]  # fmt: skip
    for i, line in enumerate(written):  # each once its own file is there, before the next's
        name = line.split(":")[0].removeprefix("written ")
        assert name in seen[line] and len(seen[line]) == i + 1
    left = [i for i, line in enumerate(lines) if line.startswith("left out ")]
    assert [lines[i].split(":")[0] for i in left] == ["left out amplitude_sweep", "left out regime"]
    assert min(left) > lines.index(f"written {out / 'summary.json'}")
    assert "f_out: far-end output peak" in "\n".join(lines[: lines.index(written[0])])
