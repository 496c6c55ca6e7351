"""Signal processing on synthetic signals with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import chirp

from analysis.envelope import decay_time, envelope
from analysis.spectra import amplitude_spectrum, n_fft_for, peak_frequency, spectrum_db
from analysis.stft import ridge_frequency, stft
from analysis.transmission import energy_transmission, signal_energy, spectral_transmission

RATE = 200_000.0


def _t(duration_s: float = 0.02) -> np.ndarray:
    return np.arange(round(duration_s * RATE)) / RATE


@pytest.mark.parametrize("f_Hz", [6630.0, 8920.0, 8013.7])
def test_tone_peak_at_its_frequency(f_Hz: float) -> None:
    t = _t()
    x = np.sin(2 * np.pi * f_Hz * t + 0.3)
    spec = amplitude_spectrum(x, RATE)
    df = spec.freq_Hz[1] - spec.freq_Hz[0]
    assert df == pytest.approx(RATE / n_fft_for(t.size))
    # zero padding x4 gives ~12 Hz bins on a 20 ms record; the parabola does better than a bin
    assert abs(float(peak_frequency(spec)) - f_Hz) < 0.25 * df


def test_gaussian_packet_level_matches_the_fourier_transform() -> None:
    t = _t()
    sigma, f0, amp = 0.4e-3, 8000.0, 3.0e-3
    x = amp * np.exp(-((t - 0.01) ** 2) / (2 * sigma**2)) * np.cos(2 * np.pi * f0 * (t - 0.01))
    spec = amplitude_spectrum(x, RATE)
    expected = amp * sigma * math.sqrt(2 * math.pi) / 2  # |X(f0)| in m/s * s
    k = int(np.argmin(np.abs(spec.freq_Hz - f0)))
    assert spec.magnitude[k] == pytest.approx(expected, rel=0.01)


def test_nan_records_give_nan_and_leave_others_alone() -> None:
    t = _t(0.005)
    x = np.stack([np.sin(2 * np.pi * 7000 * t), np.full(t.size, np.nan)])
    spec = amplitude_spectrum(x, RATE)
    assert np.all(np.isfinite(spec.magnitude[0]))
    assert np.all(np.isnan(spec.magnitude[1]))
    peaks = peak_frequency(spec, 1000, 20000)
    assert abs(peaks[0] - 7000) < 50 and np.isnan(peaks[1])
    assert np.isnan(spectrum_db(spec.magnitude)[1]).all()


def test_peak_search_range_excludes_a_stronger_tone_outside() -> None:
    t = _t()
    x = 10 * np.sin(2 * np.pi * 500 * t) + np.sin(2 * np.pi * 8000 * t)
    spec = amplitude_spectrum(x, RATE)
    assert abs(float(peak_frequency(spec)) - 500) < 20
    assert abs(float(peak_frequency(spec, 4000, 12000)) - 8000) < 20


def test_bad_sample_rate_is_refused() -> None:
    with pytest.raises(ValueError, match="sample rate"):
        amplitude_spectrum(np.zeros(16), 0.0)
    with pytest.raises(ValueError, match="sample rate"):
        signal_energy(np.zeros(16), -1.0)


def test_known_decay_time_is_recovered() -> None:
    t = _t(0.03)
    tau = 2.5e-3
    x = np.where(t > 1e-3, np.exp(-(t - 1e-3) / tau) * np.sin(2 * np.pi * 8000 * t), 0.0)
    assert decay_time(t, x) == pytest.approx(tau, rel=0.03)
    env = envelope(x)
    k = np.searchsorted(t, 5e-3)
    assert env[k] == pytest.approx(math.exp(-(t[k] - 1e-3) / tau), rel=0.03)


def test_no_decay_gives_nan() -> None:
    t = _t(0.01)
    assert math.isnan(decay_time(t, np.zeros_like(t)))


def test_chirp_ridge_follows_the_instantaneous_frequency() -> None:
    t = _t(0.02)
    f0, f1 = 4000.0, 12000.0
    x = chirp(t, f0=f0, t1=t[-1], f1=f1, method="linear")
    s = stft(x, RATE, window_s=1e-3, hop_s=0.25e-3)
    assert s.magnitude.shape == (s.freq_Hz.size, s.time_s.size)
    ridge = ridge_frequency(s, 1000, 20000)
    expected = f0 + (f1 - f0) * s.time_s / t[-1]
    inner = (s.time_s > 1e-3) & (s.time_s < t[-1] - 1e-3)
    # 1 ms Hann frames on a 400 kHz/s chirp: sweep within a frame 400 Hz; bins 250 Hz
    assert np.max(np.abs(ridge[inner] - expected[inner])) < 300
    # rising: the ridge is monotonic to within one bin
    assert np.all(np.diff(ridge[inner]) > -300)


def test_stft_ridge_is_nan_where_silent() -> None:
    t = _t(0.01)
    x = np.where(t < 4e-3, np.sin(2 * np.pi * 8000 * t), 0.0)
    s = stft(x, RATE)
    ridge = ridge_frequency(s, 1000, 20000)
    assert np.all(np.isnan(ridge[s.time_s > 6e-3]))
    assert np.nanmedian(ridge[s.time_s < 3e-3]) == pytest.approx(8000, abs=150)


def test_energy_and_spectral_transmission_of_a_scaled_copy() -> None:
    t = _t(0.01)
    near = np.exp(-((t - 3e-3) ** 2) / (2 * (0.3e-3) ** 2)) * np.sin(2 * np.pi * 8000 * t)
    far = 0.1 * np.roll(near, 400)
    assert signal_energy(near, RATE) == pytest.approx(np.sum(near**2) / RATE)
    assert float(energy_transmission(near, far, RATE)) == pytest.approx(0.01, rel=1e-6)
    sn, sf = amplitude_spectrum(near, RATE), amplitude_spectrum(far, RATE)
    tr = spectral_transmission(sn, sf)
    ok = np.isfinite(tr)
    assert ok.sum() > 10
    assert np.allclose(tr[ok], 0.1, rtol=0.02)
    # where the near spectrum is empty the ratio is not reported
    assert np.isnan(tr[np.argmin(np.abs(sn.freq_Hz - 50_000))])


def test_energy_transmission_nan_for_unmeasured() -> None:
    x = np.ones((2, 10))
    x[1] = np.nan
    tr = energy_transmission(x, x, RATE)
    assert tr[0] == pytest.approx(1.0) and np.isnan(tr[1])


def test_an_output_peak_is_not_a_maximum_on_the_search_ranges_edge() -> None:
    """A second reader: at alpha 0.7-0.9 the far end's low-frequency content, falling through
    the search range's lower edge, was read as a line there (2.10 kHz for a 2.09 kHz bound)."""
    from analysis.spectra import Spectrum

    f = np.arange(0.0, 20_000.0, 50.0)
    falling = 1.0 / (1.0 + f / 300.0)  # content below the range, falling through it
    line = 0.5 * np.exp(-(((f - 8000.0) / 200.0) ** 2))
    spec = Spectrum(f, np.stack([falling, falling + line]))
    edge = peak_frequency(spec, 2000, 12000)
    assert edge[0] == 2000.0  # the old answer: the range's first bin
    inner = peak_frequency(spec, 2000, 12000, interior=True)
    assert np.isnan(inner[0]) and abs(inner[1] - 8000.0) < 1.0
