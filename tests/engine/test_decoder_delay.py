"""The decoder delay undone by a band-limited shift (``daq.engine.decoder_delay``)."""

from __future__ import annotations

import numpy as np
import pytest

from daq.engine.decoder_delay import undo_decoder_delay


def _burst(t: np.ndarray) -> np.ndarray:
    """A narrowband burst at 8.92 kHz centred at 8 ms (Gaussian envelope, 0.4 ms wide)."""
    return np.exp(-0.5 * ((t - 8e-3) / 0.4e-3) ** 2) * np.sin(2 * np.pi * 8920.0 * (t - 8e-3))


@pytest.mark.parametrize(("rate", "delay"), [(200e3, 7.3e-6), (500e3, 7.3e-6), (50e3, 33e-6)])
def test_a_burst_delayed_by_a_fraction_of_a_sample_comes_back_exactly(
    rate: float, delay: float
) -> None:
    t = np.arange(int(0.02 * rate)) / rate
    out = undo_decoder_delay(_burst(t - delay), rate, delay)
    assert np.max(np.abs(out - _burst(t))) < 1e-9
    lin = np.interp(t + delay, t, _burst(t - delay))  # what it replaced: 0.3-4 % of the peak
    assert np.max(np.abs(lin - _burst(t))) > 1e-3


def test_a_record_that_does_not_end_quiet_is_exact_away_from_its_last_samples() -> None:
    rate, delay = 200e3, 7.3e-6
    t = np.arange(4000) / rate
    out = undo_decoder_delay(np.sin(2 * np.pi * 8920.0 * (t - delay) + 0.3), rate, delay)
    err = np.abs(out - np.sin(2 * np.pi * 8920.0 * t + 0.3))
    assert err[5:-5].max() < 5e-3 and err[20:-20].max() < 1e-4  # linear: 1e-2 everywhere
    assert np.all(np.isfinite(out)) and out.dtype == np.float64


def test_no_delay_and_tiny_records_are_copies() -> None:
    x = np.array([1.0, -2.0, 3.0])
    for v, d in ((x, 0.0), (x[:1], 5e-6)):
        out = undo_decoder_delay(v, 1e5, d)
        assert np.array_equal(out, v) and out is not v
