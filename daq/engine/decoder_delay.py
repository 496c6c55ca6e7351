"""Undoing the vibrometer decoder's delay on a record, without low-passing it.

The OFV-5000's analog velocity output lags the surface by the decoder's signal delay (a few
microseconds: 7.3 us on the simulated bench), a fraction of a sample at the rates a scan uses.
Linear interpolation between samples (``np.interp``) shifted the record but also low-passed it:
an 8.92 kHz burst came out 1.0 % too small at 200 kS/s and 0.16 % at 500 kS/s, and
``biafc calibrate`` read the piezo stroke 12-28 standard errors low on the simulated bench.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: samples read past the window beyond the delay itself: the shift's error at a record's end
#: (where the mirror image stands in for data) falls below 1e-4 of a sine's amplitude 20
#: samples in (tests/engine/test_decoder_delay.py)
TAIL_MARGIN = 24


def tail_samples(delay_s: float, rate_Hz: float) -> int:
    """How many samples (at ``rate_Hz``, S/s) to read past a record's window so that
    :func:`undo_decoder_delay` by ``delay_s`` (s) is exact to its last sample; 0 without a
    delay."""
    if not delay_s > 0.0:
        return 0
    return math.ceil(delay_s * rate_Hz) + TAIL_MARGIN


def undo_decoder_delay(
    v: NDArray[np.float64], rate_Hz: float, delay_s: float
) -> NDArray[np.float64]:
    """The record ``v [S]`` (any unit) sampled at ``rate_Hz`` (S/s), advanced by ``delay_s``
    (s): ``out(t) = v(t + delay)``, as a band-limited shift (a phase ramp on the spectrum).

    The record is extended by its mirror image before the transform, so that the periodic
    signal the transform assumes has no jump at either end; ``out`` near the record's end, where
    ``t + delay`` lies past the last sample, holds the mirrored values (the run engine reads
    :func:`tail_samples` past its window, so none of them is kept). At the record's start the
    mirror puts a kink: a record that does not start quiet (no pre-trigger) is off there by up
    to 2e-4 of its amplitude over its first ~5 samples at 500 kS/s, a few per cent at 50 kS/s.
    Within the record the shift is exact for a signal below half the rate (an 8.92 kHz burst
    at 200 kS/s: about 1e-9 of its peak away from the ends, against 1e-2 for linear
    interpolation)."""
    x = np.asarray(v, dtype=np.float64)
    n = x.shape[-1]
    if delay_s == 0.0 or n < 2:
        return x.copy()
    ext = np.concatenate([x, x[::-1]])
    spectrum = np.fft.rfft(ext)
    f_Hz = np.fft.rfftfreq(2 * n, 1.0 / rate_Hz)
    spectrum *= np.exp(2j * np.pi * f_Hz * delay_s)
    return np.fft.irfft(spectrum, 2 * n)[:n]
