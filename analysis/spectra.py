"""Fourier spectra of transient records (velocity or drive), and their peaks.

Choices (one place, stated once):

- **Window**: a Tukey (tapered cosine) window with ``TUKEY_ALPHA = 0.1``: flat over the middle
  90 % of the record and tapered over 5 % at each end. A record holds a whole transient (a
  burst and its transit), so the window only removes the step where the record is cut; it does
  not widen the burst's own spectrum the way a Hann window would.
- **Zero padding**: to ``PAD_FACTOR = 4`` times the record length, rounded up to a power of
  two, so peaks are read on a grid four times finer than ``1 / record length``; peaks are then
  refined by a parabola through the three highest bins.
- **Scaling**: the magnitude approximates the continuous Fourier transform
  ``|X(f)| = |sum x[n] w[n] exp(-2 pi i f n dt)| dt``, in the signal's unit times seconds
  (velocity in m/s gives m). The window is 1 over its flat part, so a transient lying inside
  the flat 90 % of the record keeps its exact level (a steady tone reads about 5 % low).

Records that hold NaN (points not measured) give NaN spectra: gaps stay gaps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "PAD_FACTOR",
    "TUKEY_ALPHA",
    "Spectrum",
    "amplitude_spectrum",
    "n_fft_for",
    "peak_frequency",
    "spectrum_db",
    "tukey",
    "window_for",
]

#: fraction of the record that is tapered (Tukey window parameter)
TUKEY_ALPHA = 0.1
#: zero padding: FFT length >= PAD_FACTOR * record length (rounded up to a power of two)
PAD_FACTOR = 4


@dataclass(frozen=True)
class Spectrum:
    """One-sided magnitude spectra.

    Attributes
    ----------
    freq_Hz:
        Frequencies ``[F]`` in Hz, from 0 to the Nyquist frequency.
    magnitude:
        ``[..., F]``: |Fourier transform| in (signal unit) * s; NaN where the record was not
        measured.
    """

    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]

    def band(self, f_min_Hz: float, f_max_Hz: float) -> Spectrum:
        """The part of the spectrum with ``f_min_Hz <= f <= f_max_Hz``."""
        sel = (self.freq_Hz >= f_min_Hz) & (self.freq_Hz <= f_max_Hz)
        return Spectrum(self.freq_Hz[sel], self.magnitude[..., sel])


def n_fft_for(n_samples: int, pad_factor: int = PAD_FACTOR) -> int:
    """FFT length for a record of ``n_samples``: a power of two >= ``pad_factor * n_samples``."""
    if n_samples < 1:
        raise ValueError(f"a record needs at least one sample, got {n_samples}")
    return 1 << math.ceil(math.log2(max(2, pad_factor * n_samples)))


def window_for(n_samples: int) -> NDArray[np.float64]:
    """The analysis window ``[n_samples]``: Tukey (``TUKEY_ALPHA``), 1 over its flat part."""
    return tukey(n_samples, TUKEY_ALPHA)


def tukey(n_samples: int, alpha: float) -> NDArray[np.float64]:
    """The symmetric Tukey window ``[n_samples]`` of taper fraction ``alpha`` (0: rectangular,
    1: Hann), by the formula of ``scipy.signal.windows.tukey(n_samples, alpha, sym=True)``,
    which it equals (``tests/analysis/test_spectra.py``): not imported from there, because
    importing ``scipy.signal`` took 0.7-1.1 s of every command that draws a spectrum."""
    if n_samples <= 1 or alpha <= 0.0:
        return np.ones(max(n_samples, 0))
    if alpha >= 1.0:  # Hann, as scipy writes it
        return 0.5 + 0.5 * np.cos(np.linspace(-np.pi, np.pi, n_samples))
    n = np.arange(0, n_samples, dtype=np.float64)
    width = math.floor(alpha * (n_samples - 1) / 2.0)
    n1 = n[0 : width + 1]
    n3 = n[n_samples - width - 1 :]
    w1 = 0.5 * (1 + np.cos(np.pi * (-1 + 2.0 * n1 / alpha / (n_samples - 1))))
    w2 = np.ones(n_samples - n1.size - n3.size)
    w3 = 0.5 * (1 + np.cos(np.pi * (-2.0 / alpha + 1 + 2.0 * n3 / alpha / (n_samples - 1))))
    return np.concatenate((w1, w2, w3))


def amplitude_spectrum(
    signal: ArrayLike,
    sample_rate_Hz: float,
    *,
    pad_factor: int = PAD_FACTOR,
    detrend: bool = True,
) -> Spectrum:
    """Magnitude spectrum of records sampled at ``sample_rate_Hz`` along the last axis.

    Parameters
    ----------
    signal:
        ``[..., S]`` samples (any unit U); a record holding any NaN gives an all-NaN spectrum.
    sample_rate_Hz:
        Sampling rate in Hz, > 0.
    pad_factor:
        Zero padding (see :func:`n_fft_for`).
    detrend:
        Remove each record's mean first (an offset would otherwise leak into low frequencies).

    Returns
    -------
    Spectrum with ``freq_Hz [F]`` (``F = n_fft // 2 + 1``) and ``magnitude [..., F]`` in U*s.
    """
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample rate must be > 0 Hz, got {sample_rate_Hz!r}")
    x = np.asarray(signal, dtype=np.float64)
    if x.ndim == 0 or x.shape[-1] < 2:
        raise ValueError(f"a record needs at least 2 samples along its last axis, got {x.shape}")
    n = x.shape[-1]
    bad = ~np.all(np.isfinite(x), axis=-1)
    x = np.where(np.isfinite(x), x, 0.0)
    if detrend:
        x = x - x.mean(axis=-1, keepdims=True)
    n_fft = n_fft_for(n, pad_factor)
    dt = 1.0 / sample_rate_Hz
    mag = np.asarray(np.abs(np.fft.rfft(x * window_for(n), n=n_fft, axis=-1)) * dt, np.float64)
    mag[bad] = np.nan
    freq = np.asarray(np.fft.rfftfreq(n_fft, dt), np.float64)
    return Spectrum(freq, mag)


def peak_frequency(
    spectrum: Spectrum,
    f_min_Hz: float = 0.0,
    f_max_Hz: float = math.inf,
    *,
    interior: bool = False,
) -> NDArray[np.float64]:
    """Frequency (Hz) of the largest magnitude in ``[f_min_Hz, f_max_Hz]``, for every record.

    Refined by a parabola through the highest bin and its neighbours. Returns ``[...]`` (the
    spectrum's leading shape); NaN for records that are NaN or have no bin in the range.
    ``interior``: a largest magnitude on the range's first or last bin (the spectrum still
    rising out of the range: its line lies outside) is no peak, NaN; the output peaks take it
    (a chain's low-frequency content read as a line at the search range's lower edge, 2.1 kHz
    for an 8.92 kHz drive).
    """
    sel = (spectrum.freq_Hz >= f_min_Hz) & (spectrum.freq_Hz <= f_max_Hz)
    lead = spectrum.magnitude.shape[:-1]
    if not np.any(sel):
        return np.full(lead, np.nan)
    f = spectrum.freq_Hz[sel]
    m = spectrum.magnitude[..., sel].reshape(-1, f.size)
    out = np.full(m.shape[0], np.nan)
    df = f[1] - f[0] if f.size > 1 else 0.0
    for i, row in enumerate(m):
        if not np.all(np.isfinite(row)) or not np.any(row > 0):
            continue
        k = int(np.argmax(row))
        if interior and f.size > 2 and k in (0, f.size - 1):
            continue
        fk = float(f[k])
        if 0 < k < f.size - 1:
            a, b, c = row[k - 1], row[k], row[k + 1]
            denom = a - 2.0 * b + c
            if denom < 0:
                fk += 0.5 * (a - c) / denom * df
        out[i] = fk
    return out.reshape(lead)


def spectrum_db(magnitude: NDArray[Any], reference: float | None = None) -> NDArray[np.float64]:
    """Magnitude in dB relative to ``reference`` (default: the largest finite magnitude).

    Shape as ``magnitude``; values floored at -120 dB; NaN stays NaN.
    """
    m = np.asarray(magnitude, dtype=np.float64)
    if reference is None:
        finite = m[np.isfinite(m)]
        reference = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        db = 20.0 * np.log10(np.maximum(m, reference * 1e-6) / reference)
    return np.where(np.isfinite(m), db, np.nan)
