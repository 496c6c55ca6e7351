"""The far end at the noise floor: a bound, not a measurement (a second reader found the
shipped sweep's figures calling the RTL conversion at 5 um "none": its linear reference, the
10 nm point, was the digitiser's noise, and so were the output peaks of the small drives)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.noise_floor import RESOLVED_FACTOR, noise_energy, resolved
from analysis.summary import format_summary, summarize, summary_rows
from analysis.sweep import amplitude_sweep, input_frequency_Hz, linear_reference
from daq.cli.run_protocol import main as run_protocol
from protocols.runfile import read_run

PROTOCOL = """\
name: noise_floor
directions: both
burst:
  ltr: {f_center: 8.92 kHz, shape: narrowband}
  rtl: {f_center: 6.63 kHz, shape: narrowband}
amplitudes: [10 nm, 143 nm, 5 um]
cylinders: [1, 31]
averages: 2
acquisition: {rate: 500 kS/s, duration: 25 ms, pre_trigger: 1 ms}
settle: 50 ms
order: [direction, amplitude, cylinder]
on_point_failure: continue
"""


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped sweep's settings (and its default range, 10 mm/s/V) at three amplitudes,
    on the end cylinders only."""
    folder = tmp_path_factory.mktemp("noise")
    protocol = folder / "noise_floor.yaml"
    protocol.write_text(PROTOCOL)
    out = folder / "run.h5"
    assert run_protocol([str(protocol), "--out", str(out), "-q"]) == 0
    return out


def test_noise_energy_is_the_pre_trigger_mean_square_over_the_record() -> None:
    t = np.arange(-20, 80) / 1e3
    x = np.where(t < 0, 2.0, 0.5)[None, :] * np.ones((3, 1))
    e = noise_energy(x, t, 1e3)
    assert e.shape == (3,) and np.allclose(e, 4.0 * 100 / 1e3)
    assert np.all(np.isnan(noise_energy(x[:, 10:], t[10:], 1e3)))  # 10 samples: no estimate
    assert list(resolved([1.0, 3.9, 4.0, np.nan, 1.0], [np.nan, 1.0, 1.0, 1.0, 0.0])) == [
        True, False, True, False, True,
    ]  # fmt: skip
    assert RESOLVED_FACTOR == 4.0


def test_the_linear_reference_is_the_tightest_bound_below_the_first_resolved_point() -> None:
    amps = np.array([1.0, 2.0, 3.0, 4.0])
    t = np.array([0.1, 0.02, 0.03, 0.5])
    floor = np.array([True, True, False, False])
    bound = np.array([0.4, 0.08, np.nan, np.nan])
    assert linear_reference(amps, t, floor, bound) == (0.03, False)  # within the bounds
    assert linear_reference(amps, t * [1, 1, 3, 1], floor, bound) == (0.08, True)
    assert linear_reference(amps, t, np.zeros(4, bool), bound) == (0.1, False)
    assert np.isnan(linear_reference(amps[:1], t[:1], floor[:1], bound[:1])[0])


def test_points_at_the_noise_floor_are_bounds_and_the_conversion_still_shows(
    small_sweep: Path,
) -> None:
    summary = summarize(read_run(small_sweep))
    rows = {(r["direction"], round(r["amplitude"] * 1e9)): r for r in summary["rows"]}
    for d, nm in (("ltr", 10), ("rtl", 10), ("rtl", 143)):
        row = rows[(d, nm)]
        assert row["at_noise_floor"] and row["conversion"] == "none", row
        assert row["output_Hz"] is None and row["transmission_gain"] is None
        assert row["far_noise_ratio"] < RESOLVED_FACTOR
        # a bound on the far end's energy within the band where the signal can be (the
        # whole record's E_far/E_in holds the broadband noise too)
        assert 0 < row["transmission_upper_bound"] < row["transmission"]
    for d in ("ltr", "rtl"):
        high = rows[(d, 5000)]
        assert not high["at_noise_floor"] and high["far_noise_ratio"] > 100
        assert high["transmission_gain"] >= 10
    # LTR's linear leak at 143 nm stands above the noise in its band (a line near 8.2 kHz,
    # below the 10 nm bound): it is the linear reference itself, and nothing converted
    lin = rows[("ltr", 143)]
    assert not lin["at_noise_floor"] and lin["far_noise_ratio"] > 10 * RESOLVED_FACTOR
    assert lin["transmission_gain"] == pytest.approx(1.0) and lin["conversion"] == "none"
    assert not rows[("ltr", 5000)]["gain_is_lower_bound"]
    assert rows[("rtl", 5000)]["gain_is_lower_bound"]
    # the paper's claim: converted down from the left, up from the right
    assert rows[("ltr", 5000)]["conversion"] == "down"
    assert rows[("rtl", 5000)]["conversion"] == "up"
    text = format_summary(summary)
    assert "<x: the far end held less than 4x the energy its own pre-trigger noise gives" in text
    assert "in the band where it can be (ltr 6.69-10.26 kHz" in text
    assert ">=" in text
    # one quantity per column (a reviewer): the whole records' ratio, and the far end's
    # signal with its bound, of which the gains are
    header = next(line for line in text.splitlines() if line.startswith("dir"))
    assert "E_far/E_in" in header and "E_sig/E_in" in header
    row10 = next(line for line in text.splitlines() if line.startswith("ltr") and "10 nm" in line)
    whole, signal = row10.split()[7:9]
    assert not whole.startswith("<") and signal.startswith("<"), row10
    assert rows[("ltr", 5000)]["transmission_gain"] == pytest.approx(
        rows[("ltr", 5000)]["signal_transmission"] / rows[("ltr", 143)]["signal_transmission"]
    )


def test_the_input_frequency_is_the_median_of_the_drive_records() -> None:
    """One noisy drive record at a small drive gave 8.887 kHz for an 8.92 kHz carrier."""
    rate, n = 500e3, 12_500
    t = np.arange(n) / rate
    rng = np.random.default_rng(1)

    def drive(f_Hz: float) -> np.ndarray:
        return np.sin(2 * np.pi * f_Hz * t) + 0.01 * rng.standard_normal(n)

    records = np.stack([drive(8860.0), drive(8920.0), drive(8920.0)])[None].astype(np.float32)

    class Scan:
        amplitudes = np.array([1e-8])
        cylinders = np.array([1, 2, 3])
        done = np.ones((1, 3), np.uint8)
        f_center_Hz = 8920.0
        sample_rate_Hz = rate

    Scan.drive = records  # type: ignore[attr-defined]
    assert input_frequency_Hz(Scan()) == pytest.approx([8920.0], abs=5.0)  # type: ignore[arg-type]


def test_a_far_end_at_the_noise_floor_counts_as_measured_for_the_sweep_figures(
    small_sweep: Path, tmp_path: Path
) -> None:
    """Its output peak is not given, but the point was measured: the sweep and regime figures
    are drawn (they were left out: "far cylinder 31 measured at 1 amplitude(s)")."""
    from analysis.report import write_figures

    report = write_figures(read_run(small_sweep), tmp_path)
    assert {"amplitude_sweep", "regime"} <= set(report.figures), report.skipped


def test_a_sweep_wholly_at_the_noise_floor_draws_its_figures(tmp_path: Path) -> None:
    """A reviewer: with every far record at the noise floor, biafc figures ended in "Data
    cannot be log-scaled" (exit 2) and wrote no summary."""
    from daq.cli.biafc import main as biafc

    protocol = tmp_path / "small.yaml"
    protocol.write_text(PROTOCOL.replace("[10 nm, 143 nm, 5 um]", "[10 nm, 143 nm]"))
    out = tmp_path / "small.h5"
    assert run_protocol([str(protocol), "--out", str(out), "-q"]) == 0
    assert biafc(["figures", str(out), "--out", str(tmp_path / "f")]) == 0
    assert (tmp_path / "f" / "amplitude_sweep.png").exists()
    assert (tmp_path / "f" / "summary.json").exists()


def test_the_far_record_alone_decides_the_noise_floor(small_sweep: Path) -> None:
    """A reviewer: with the entry point failed, a far record at the noise floor kept its noise
    line as the output peak (8.175 kHz for the 8.92 kHz drive)."""
    run = read_run(small_sweep)
    scan = run.scans["rtl"]
    entry = int(np.flatnonzero(scan.cylinders == 31)[0])  # RTL enters at cylinder 31
    scan.velocity[:, entry, :] = np.nan
    sweep = amplitude_sweep(scan, run.chain)
    assert list(sweep.at_noise_floor) == [True, True, False]
    assert np.all(np.isnan(sweep.output_Hz[:2])) and np.all(np.isnan(sweep.transmission))


def test_a_measured_point_without_a_peak_inside_the_range_is_not_unmeasured(
    small_sweep: Path,
) -> None:
    """A reviewer: a resolved point whose largest line sat on the search range's edge (so no
    output peak) was called "not measured" beside its transmission and gain."""
    import dataclasses

    run = read_run(small_sweep)
    sweep = amplitude_sweep(run.scans["ltr"], run.chain)
    no_peak = sweep.output_Hz.copy()
    no_peak[2] = np.nan
    edged = dataclasses.replace(sweep, output_Hz=no_peak, detuning_Hz=no_peak - sweep.input_Hz)
    row = summary_rows(edged, run.scans["ltr"])[2]
    assert row["transmission"] is not None and row["conversion"] == "undetermined"
    # with no linear reference the energy rule decides, as everywhere (a reviewer)
    alone = dataclasses.replace(
        edged, transmission_gain=np.full(3, np.nan), reference=np.nan, reference_is_bound=False
    )
    tr = float(alone.transmission[2])
    want = "undetermined" if tr >= 1e-2 else "none"
    assert summary_rows(alone, run.scans["ltr"])[2]["conversion"] == want == "undetermined"
    quiet = dataclasses.replace(alone, transmission=np.where(np.arange(3) == 2, 1e-4, np.nan))
    assert summary_rows(quiet, run.scans["ltr"])[2]["conversion"] == "none"


def test_a_run_without_pre_trigger_says_it_has_no_noise_estimate(tmp_path: Path) -> None:
    """A reviewer: without pre-trigger samples the summary fell back to the old answers
    (a noise line as the peak) without a word."""
    protocol = tmp_path / "nopre.yaml"
    protocol.write_text(PROTOCOL.replace("pre_trigger: 1 ms", "pre_trigger: 0 ms"))
    out = tmp_path / "nopre.h5"
    assert run_protocol([str(protocol), "--out", str(out), "-q"]) == 0
    summary = summarize(read_run(out))
    assert summary["noise_unknown"] == ["ltr", "rtl"]
    assert "ltr: no noise estimate (its records have fewer than 16 pre-trigger" in format_summary(
        summary
    )


def test_the_detuning_panel_holds_every_directions_amplitudes(small_sweep: Path) -> None:
    """A reviewer: the panel's range was set per direction, so the last one's won and hid the
    other's points."""
    import dataclasses

    from analysis.plots.sweep_plot import plot_amplitude_sweep

    run = read_run(small_sweep)
    ltr = amplitude_sweep(run.scans["ltr"], run.chain)
    rtl = amplitude_sweep(run.scans["rtl"], run.chain)
    rtl = dataclasses.replace(rtl, amplitudes=rtl.amplitudes * 100)  # 1 um to 500 um
    fig = plot_amplitude_sweep({"ltr": ltr, "rtl": rtl})
    panel = next(ax for ax in fig.axes if ax.get_xlabel().startswith("detuning"))
    low, high = panel.get_ylim()
    assert low < 10e-9 * 1e6 and high > 500e-6 * 1e6  # in um, both directions inside


def test_a_sweep_without_its_entry_cylinder_leaves_the_regime_figure_out(tmp_path: Path) -> None:
    """A reviewer: with no far/near ratio at all (the entry cylinder not scanned) the regime
    figure's log axes had nothing and biafc figures ended in "Data cannot be log-scaled"."""
    from daq.cli.biafc import main as biafc

    protocol = tmp_path / "far_only.yaml"
    protocol.write_text(
        PROTOCOL.replace("directions: both", "directions: [ltr]").replace(
            "cylinders: [1, 31]", "cylinders: [16, 31]"
        )
    )
    out = tmp_path / "far_only.h5"
    assert run_protocol([str(protocol), "--out", str(out), "-q"]) == 0
    assert biafc(["figures", str(out), "--out", str(tmp_path / "f")]) == 0
    summary = json.loads((tmp_path / "f" / "summary.json").read_text())
    assert "entry cylinder was not measured" in summary["figures_left_out"]["regime"]


def test_a_narrowband_far_line_is_set_against_the_noise_in_its_own_band(
    small_sweep: Path,
) -> None:
    """A second reader: on the simulated bench, linear_lowamp's LTR far end (a line near
    8.2 kHz standing about 10x above the noise in its band) read "E_far/E_in < 0.00307": the
    energies were compared over the whole 0..250 kHz record, where broadband digitiser noise
    hides a narrowband line. A far record whose burst-band line holds 1.5x the whole record's
    noise energy stands far above the noise within the band where the signal can be."""
    run = read_run(small_sweep)
    scan = run.scans["ltr"]
    far = int(np.flatnonzero(scan.cylinders == 31)[0])
    t = scan.time_s
    rate = scan.sample_rate_Hz
    rng = np.random.default_rng(7)
    noise = 1e-6 * rng.standard_normal(t.size)
    line = np.exp(-(((t - 8e-3) / 0.5e-3) ** 2) / 2) * np.sin(2 * np.pi * 8200.0 * t)
    e_noise = np.sum(noise**2) / rate
    line *= np.sqrt(1.5 * e_noise / (np.sum(line**2) / rate))
    scan.velocity[0, far, :] = (noise + line).astype(np.float32)
    sweep = amplitude_sweep(scan, run.chain)
    assert not sweep.at_noise_floor[0], sweep.far_noise_ratio[0]
    assert sweep.far_noise_ratio[0] > 10 * RESOLVED_FACTOR
    assert sweep.output_Hz[0] == pytest.approx(8200.0, abs=150.0)
    # noise alone stays at the noise floor, bounded in its band (not over the whole record)
    scan.velocity[0, far, :] = noise.astype(np.float32)
    quiet = amplitude_sweep(scan, run.chain)
    assert quiet.at_noise_floor[0] and np.isnan(quiet.output_Hz[0])
    lo, hi = quiet.signal_band_Hz
    assert lo < 8200.0 < hi and 8920.0 < hi and hi - lo < 0.02 * rate / 2
    e_entry = np.sum(scan.velocity[0, 0, :].astype(float) ** 2) / rate
    assert quiet.transmission_bound[0] < 0.1 * RESOLVED_FACTOR * e_noise / e_entry


def test_band_noise_energy_is_the_pre_trigger_noise_in_the_band() -> None:
    """White noise: the band's share of the whole record's noise energy, from the pre-trigger
    samples measured over a wider level band."""
    from analysis.noise_floor import band_energy, band_noise_energy

    rng = np.random.default_rng(3)
    rate = 100e3
    t = (np.arange(5000) - 500) / rate
    x = rng.standard_normal((64, t.size))
    whole = noise_energy(x, t, rate)
    band = band_noise_energy(x, t, rate, (8e3, 12e3), (4e3, 16e3))
    assert np.mean(band / whole) == pytest.approx(4e3 / 50e3, rel=0.1)
    assert np.mean(band_energy(x, rate, (8e3, 12e3)) / band) == pytest.approx(1.0, rel=0.1)
    assert np.all(np.isnan(band_noise_energy(x[:, 490:], t[490:], rate, (8e3, 12e3))))


def test_pure_noise_is_rarely_resolved_even_with_a_short_pre_trigger(small_sweep: Path) -> None:
    """A reviewer's Monte Carlo: over the level band, a 0.2 ms pre-trigger at 500 kS/s holds
    about 4 degrees of freedom, and white noise stood "resolved" in 5.7 % of records (18 % at
    0.05 ms). Below MIN_BAND_DOF the whole record decides, as it did before."""
    import dataclasses

    from analysis.noise_floor import MIN_BAND_DOF, band_dof

    run = read_run(small_sweep)
    scan = run.scans["ltr"]
    keep = scan.time_s >= -0.2e-3  # 0.2 ms before the trigger
    t = scan.time_s[keep]
    n_amp = 400
    rng = np.random.default_rng(11)
    noise = rng.normal(0.0, 1e-5, (n_amp, scan.cylinders.size, t.size)).astype(np.float32)
    amps = np.geomspace(1e-8, 5e-6, n_amp)
    per_point = np.ones((n_amp, scan.cylinders.size))
    only_noise = dataclasses.replace(
        scan, amplitudes=amps, time_s=t, velocity=noise, drive=noise,
        done=np.ones((n_amp, scan.cylinders.size), np.uint8), measured_at=per_point,
        fail_reason=np.full((n_amp, scan.cylinders.size), "", dtype=object),
        sensitivity_m_per_s_per_V=per_point, decoder_delay_undone_s=per_point * 0,
    )  # fmt: skip
    sweep = amplitude_sweep(only_noise, run.chain)
    assert band_dof(t, only_noise.sample_rate_Hz, sweep.f_range_Hz) < MIN_BAND_DOF
    assert sweep.signal_band_Hz == (0.0, only_noise.sample_rate_Hz / 2)  # the whole record
    assert np.mean(~sweep.at_noise_floor) < 0.01
    # an offset is no signal (a reviewer: with the pre-trigger's mean removed and the record's
    # kept, 5 sigma of offset stood "resolved" in every record)
    offset = dataclasses.replace(only_noise, velocity=noise + np.float32(5e-5))
    assert np.mean(~amplitude_sweep(offset, run.chain).at_noise_floor) < 0.01


def test_an_offset_on_the_pre_trigger_is_not_read_as_noise_in_the_band() -> None:
    """A reviewer: the pre-trigger's mean was kept, so a DC offset on its short stretch leaked
    into the band and read as noise there (5 sigma of offset took a perfect model's noise
    reference in biafc compare from 0.17 to 0.96)."""
    from analysis.noise_floor import band_noise_energy

    rate, n = 500e3, 12_500
    t = (np.arange(n) - 500) / rate  # 1 ms before the trigger
    rng = np.random.default_rng(5)
    noise = rng.normal(0.0, 1e-4, (200, n))
    band = (6.7e3, 10.3e3)
    plain = band_noise_energy(noise, t, rate, band, (3.9e3, 13.3e3))
    offset = band_noise_energy(noise + 5e-4, t, rate, band, (3.9e3, 13.3e3))
    assert np.median(offset / plain) == pytest.approx(1.0, abs=0.05)


def test_the_summary_says_when_the_whole_record_set_the_noise(tmp_path: Path) -> None:
    """A reviewer: after the whole-record fallback the line read "in the band where it can be
    (ltr 0.00-100.00 kHz)", and it was printed when no row had an E_sig at all."""
    protocol = tmp_path / "short_pre.yaml"  # 0.3 ms before the trigger: 5.6 degrees of freedom
    protocol.write_text(PROTOCOL.replace("pre_trigger: 1 ms", "pre_trigger: 0.3 ms"))
    out = tmp_path / "short_pre.h5"
    assert run_protocol([str(protocol), "--out", str(out), "-q"]) == 0
    summary = summarize(read_run(out))
    text = format_summary(summary)
    assert summary["noise_over_whole_record"] == ["ltr", "rtl"]
    assert "ltr: the whole record, its pre-trigger too short for a band's noise" in text
    assert "0.00-250.00 kHz" not in text
    no_signal = {**summary, "rows": [{**r, "signal_transmission": None} for r in summary["rows"]]}
    assert "E_sig/E_in: the far end's signal" not in format_summary(no_signal)
