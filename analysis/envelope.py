"""Envelopes of transient records and the decay rate read from them.

The envelope is the magnitude of the analytic signal (Hilbert transform) along the last axis.
The decay rate of a ringing record ``A exp(-t / tau) cos(...)`` is read by a straight-line fit
to ``log(envelope)`` between two levels below the peak (after the peak), so the fit avoids both
the rise and the noise floor.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["analytic_signal", "decay_time", "envelope"]


def analytic_signal(signal: ArrayLike) -> NDArray[np.complex128]:
    """The analytic signal ``x + i H[x]`` of the real ``signal [..., S]`` along the last axis
    (same unit and shape), by the FFT as ``scipy.signal.hilbert`` computes it: the spectrum's
    positive frequencies doubled, its negative ones zeroed. Not imported from there, because
    importing ``scipy.signal`` took 0.7-1.1 s of every command that draws a figure."""
    x = np.asarray(signal, dtype=np.float64)
    n = x.shape[-1]
    if n == 0:
        raise ValueError("the analytic signal of an empty record")
    spectrum = np.fft.fft(x, axis=-1)
    spectrum[..., 1 : (n + 1) // 2] *= 2.0
    spectrum[..., n // 2 + 1 :] = 0.0  # n even: the Nyquist bin n/2 is kept once
    return np.asarray(np.fft.ifft(spectrum, axis=-1), dtype=np.complex128)


def envelope(signal: ArrayLike) -> NDArray[np.float64]:
    """|analytic signal| of ``signal [..., S]`` (same unit and shape); NaN records stay NaN."""
    x = np.asarray(signal, dtype=np.float64)
    bad = ~np.all(np.isfinite(x), axis=-1)
    env = np.abs(analytic_signal(np.where(np.isfinite(x), x, 0.0)))
    env[bad] = np.nan
    return np.asarray(env, dtype=np.float64)


def decay_time(
    time_s: ArrayLike,
    signal: ArrayLike,
    *,
    upper_db: float = -3.0,
    lower_db: float = -30.0,
) -> float:
    """Exponential decay time ``tau`` in s of one record ``signal [S]`` sampled at ``time_s [S]``.

    Fits ``log(envelope)`` after the peak, between ``upper_db`` and ``lower_db`` relative to
    the peak (the first time the envelope falls below ``lower_db`` ends the fit). Returns NaN
    when fewer than 8 samples fall in that range or the record does not decay.
    """
    t = np.asarray(time_s, dtype=np.float64)
    env = envelope(signal)
    if env.ndim != 1 or t.shape != env.shape:
        raise ValueError("decay_time takes one record: time_s and signal of the same shape [S]")
    if not np.all(np.isfinite(env)) or env.max() <= 0:
        return math.nan
    k = int(np.argmax(env))
    db = 20.0 * np.log10(np.maximum(env[k:], 1e-300) / env[k])
    below = np.nonzero(db < lower_db)[0]
    stop = int(below[0]) if below.size else db.size
    sel = np.nonzero(db[:stop] <= upper_db)[0]
    if sel.size < 8:
        return math.nan
    slope = np.polyfit(t[k:][sel], np.log(env[k:][sel]), 1)[0]
    return -1.0 / slope if slope < 0 else math.nan
