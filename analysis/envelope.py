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
from scipy.signal import hilbert

__all__ = ["decay_time", "envelope"]


def envelope(signal: ArrayLike) -> NDArray[np.float64]:
    """|analytic signal| of ``signal [..., S]`` (same unit and shape); NaN records stay NaN."""
    x = np.asarray(signal, dtype=np.float64)
    bad = ~np.all(np.isfinite(x), axis=-1)
    env = np.abs(hilbert(np.where(np.isfinite(x), x, 0.0), axis=-1))
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
