"""The asymmetry sweep: its result object, figure and JSON (synthetic), and its inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.alpha_sweep import (
    AlphaSweepResult,
    format_alpha_sweep,
    parse_amplitude,
    run_alpha_sweep,
    write_alpha_sweep,
)


def _result() -> AlphaSweepResult:
    alphas = np.array([0.1, 0.2, 0.3])
    freq = np.linspace(3000.0, 13000.0, 401)
    r = AlphaSweepResult(
        alphas, alphas + 0.01, {"ltr": 8920.0, "rtl": 6630.0}, ("displacement", 4e-6), 8e-3, freq
    )
    for d, f_in, sign in (("ltr", 8920.0, -1), ("rtl", 6630.0, 1)):
        out = f_in + sign * np.array([300.0, 800.0, 1300.0])
        r.magnitude[d] = np.exp(-(((freq[None, :] - out[:, None]) / 300.0) ** 2))
        r.output_Hz[d] = out
        r.expected_Hz[d] = out + 10.0
        r.transmission[d] = np.array([0.3, 0.1, np.nan])
    return r


def test_fractional_detuning_and_json(tmp_path: Path) -> None:
    r = _result()
    assert np.allclose(r.fractional_detuning("ltr"), -np.array([300, 800, 1300]) / 8920.0)
    assert np.allclose(r.expected_fractional_detuning("rtl"), np.array([310, 810, 1310]) / 6630)
    paths = write_alpha_sweep(r, tmp_path)
    assert {p.name for p in paths} == {"alpha_sweep.png", "alpha_sweep.pdf", "alpha_sweep.json"}
    data = json.loads((tmp_path / "alpha_sweep.json").read_text())
    assert data["directions"]["rtl"]["transmission"][2] is None  # NaN -> null
    assert data["alphas"] == [0.1, 0.2, 0.3]
    text = format_alpha_sweep(r)
    assert len(text.splitlines()) == 1 + 6 and "-3.36" in text


def test_parse_amplitude() -> None:
    assert parse_amplitude("2um") == ("displacement", pytest.approx(2e-6))
    assert parse_amplitude("12 N") == ("force", 12.0)
    with pytest.raises(ValueError, match="displacement"):
        parse_amplitude("3 kHz")
    with pytest.raises(ValueError, match="displacement"):
        parse_amplitude("2")


def test_bad_sweep_inputs_refused_before_any_run() -> None:
    with pytest.raises(ValueError, match="alphas"):
        run_alpha_sweep([])
    with pytest.raises(ValueError, match="alphas"):
        run_alpha_sweep([-0.1])
    with pytest.raises(ValueError, match="duration"):
        run_alpha_sweep([0.1], duration_s=0.0)


def test_defaults_are_the_papers_regime_with_a_linear_reference() -> None:
    """The sweep ran 10-cycle bursts in 8 ms windows, broad enough that the far cylinder's
    filtering alone put the linear (10 nm) peak on the predicted edge (LTR -11.07 % at alpha 0.3);
    it now runs the narrowband burst in the paper's 30 ms window, with a 10 nm reference."""
    from analysis import alpha_sweep
    from instruments.burst import NARROWBAND_CYCLES

    assert alpha_sweep.DEFAULT_CYCLES == NARROWBAND_CYCLES
    assert alpha_sweep.DEFAULT_DURATION_S >= 25e-3
    assert alpha_sweep.DEFAULT_REFERENCE_AMPLITUDE == ("displacement", pytest.approx(10e-9))


def test_alpha_verdict_tells_conversion_from_filtering_and_overlap() -> None:
    from analysis.alpha_sweep import alpha_verdict

    # passes (gain 500) and moved 11 % from the input, but the linear run's peak is 0.6 % away:
    # the far cylinder's filtering, not conversion
    assert alpha_verdict(8920.0, 7900.0, 0.05, 7950.0, 1e-4) == "filtering"
    assert alpha_verdict(8920.0, 7600.0, 0.05, 8100.0, 1e-4) == "down"
    assert alpha_verdict(6630.0, 8000.0, 0.05, 7000.0, 1e-4) == "up"
    assert alpha_verdict(8920.0, 7600.0, 0.05, 8100.0, 0.04) == "none"  # gain 1.25
    assert alpha_verdict(8920.0, 7600.0, 0.05) == "down"  # no reference: the level rule
    assert alpha_verdict(8920.0, 7600.0, 0.05, 8100.0, 1e-4, bands_overlap=True) == (
        "bands overlap"
    )


def test_bands_overlap_rule() -> None:
    from analysis.alpha_sweep import bands_overlap

    onset = np.array([9472.0, 6600.0, 3784.0])  # alpha 0.7 on the default chain
    assert bands_overlap(np.array([4061.0, 3100.0, 2133.0]), onset)
    assert not bands_overlap(np.array([3862.0, 3100.0, 2497.0]), onset + 1000.0)  # 0.5
    assert not bands_overlap(np.full(3, np.nan), onset)  # no acoustic band stored


def test_overlap_is_flagged_in_table_json_and_figure(tmp_path: Path) -> None:
    r = _result()
    r.bands_overlap = np.array([False, False, True])
    r.acoustic_cutoff_Hz = np.array([3700.0, 3900.0, 4061.0])
    r.resonance_onset_Hz = np.array([5300.0, 4600.0, 3784.0])
    assert np.isnan(r.fractional_detuning("ltr")[2]) and np.isfinite(r.output_Hz["ltr"][2])
    text = format_alpha_sweep(r).splitlines()
    assert "bands overlap" in text[5] and "3.78 kHz < acoustic cutoff 4.06 kHz" in text[5]
    assert text[5].split()[3] == "-"  # no converted line
    write_alpha_sweep(r, tmp_path)
    data = json.loads((tmp_path / "alpha_sweep.json").read_text())
    assert data["bands_overlap"] == [False, False, True]
    assert data["directions"]["ltr"]["verdict"][2] == "bands overlap"
    assert data["directions"]["ltr"]["fractional_detuning"][2] is None
    from analysis.plots.alpha_plot import plot_alpha_sweep

    fig = plot_alpha_sweep(r)
    labels = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts]
    assert any("bands overlap" in t for t in labels)


@pytest.mark.slow  # two DEM chains, about a second
def test_large_alpha_spectrum_covers_the_search_range_and_is_flagged() -> None:
    """At alpha 0.7 the peak search starts at 0.7 x the lowest onset (2.65 kHz) but the stored
    spectrum started at 0.5 x 6.63 kHz = 3.3 kHz: peaks sat on its lower edge. The spectrum now
    covers the search range, and the alpha is flagged: #31's resonance onset (3.78 kHz) lies
    below #1's acoustic cutoff (4.06 kHz)."""
    r = run_alpha_sweep([0.5, 0.7], amplitude=("displacement", 4e-6), duration_s=10e-3)
    assert r.freq_Hz[0] <= 0.7 * 3784.0 + (r.freq_Hz[1] - r.freq_Hz[0])  # first bin in range
    assert r.bands_overlap is not None and list(r.bands_overlap) == [False, True]
    assert r.resonance_onset_Hz is not None and r.acoustic_cutoff_Hz is not None
    assert r.resonance_onset_Hz[1] == pytest.approx(3784.0, rel=0.01)
    assert r.acoustic_cutoff_Hz[1] == pytest.approx(4061.0, rel=0.01)
    assert r.verdicts("ltr")[1] == r.verdicts("rtl")[1] == "bands overlap"
    assert r.verdicts("ltr")[0] == "down" and r.verdicts("rtl")[0] == "up"
    assert set(r.linear_output_Hz) == {"ltr", "rtl"}


def test_a_peak_in_the_acoustic_band_is_no_conversion() -> None:
    """alpha 0.6, RTL at 4 um: the far cylinder's peak at 2.96 kHz lies under #1's acoustic
    cutoff (3.96 kHz); it was reported as a -55 % "conversion"."""
    from analysis.alpha_sweep import alpha_verdict

    assert alpha_verdict(6630.0, 2955.0, 0.013, 7000.0, 1e-7, acoustic_cutoff_Hz=3964.0) == (
        "acoustic band"
    )
    assert alpha_verdict(6630.0, 8800.0, 0.013, 7000.0, 1e-7, acoustic_cutoff_Hz=3964.0) == "up"


def test_a_line_below_the_acoustic_cutoff_that_did_not_pass_is_no_acoustic_band() -> None:
    """A reviewer: "acoustic band" was decided before the transmission rule, so a peak there
    read "acoustic band" though nothing passed (gain 1, the linear run's own line)."""
    from analysis.alpha_sweep import alpha_verdict

    assert alpha_verdict(6630, 2960, 1e-6, 2960, 1e-6, acoustic_cutoff_Hz=3960) == "none"
    assert alpha_verdict(6630, 2960, 0.2, 6700, 1e-6, acoustic_cutoff_Hz=3960) == "acoustic band"
