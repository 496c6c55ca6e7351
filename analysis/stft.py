"""Short-time Fourier transform of records, and the ridge (peak frequency against time).

Frames: a Hann window of ``window_s`` moved by ``hop_s``; each frame zero-padded to
``PAD_FACTOR`` times its length (a power of two). Magnitude in (signal unit) * s, like
:mod:`analysis.spectra`, normalised by the window's mean. Frame times are the frame centres
in s from the trigger.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from analysis.spectra import PAD_FACTOR, n_fft_for

__all__ = ["DEFAULT_HOP_S", "DEFAULT_WINDOW_S", "Stft", "ridge_frequency", "stft"]

#: default frame length: 1 ms (frequency resolution about 1 kHz before padding; 9 cycles of 9 kHz)
DEFAULT_WINDOW_S = 1.0e-3
#: default hop between frames
DEFAULT_HOP_S = 0.25e-3


@dataclass(frozen=True)
class Stft:
    """Short-time spectra: ``time_s [T]`` (frame centres), ``freq_Hz [F]``,
    ``magnitude [..., F, T]`` in (signal unit) * s (NaN for unmeasured records)."""

    time_s: NDArray[np.float64]
    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]


def stft(
    signal: ArrayLike,
    sample_rate_Hz: float,
    *,
    window_s: float = DEFAULT_WINDOW_S,
    hop_s: float = DEFAULT_HOP_S,
    t0_s: float = 0.0,
) -> Stft:
    """STFT of ``signal [..., S]`` sampled at ``sample_rate_Hz``, first sample at ``t0_s``."""
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample rate must be > 0 Hz, got {sample_rate_Hz!r}")
    if not (window_s > 0 and hop_s > 0):
        raise ValueError(f"STFT window and hop must be > 0 s, got {window_s!r}, {hop_s!r}")
    x = np.asarray(signal, dtype=np.float64)
    n = x.shape[-1]
    nw = max(4, round(window_s * sample_rate_Hz))
    if nw > n:
        raise ValueError(f"STFT window {window_s} s is longer than the record ({n} samples)")
    nh = max(1, round(hop_s * sample_rate_Hz))
    starts = np.arange(0, n - nw + 1, nh)
    bad = ~np.all(np.isfinite(x), axis=-1)
    x = np.where(np.isfinite(x), x, 0.0)
    w = np.hanning(nw)
    w = w / w.mean()
    idx = starts[:, None] + np.arange(nw)[None, :]
    frames = x[..., idx] * w  # [..., T, nw]
    n_fft = n_fft_for(nw, PAD_FACTOR)
    mag = np.abs(np.fft.rfft(frames, n=n_fft, axis=-1)) / sample_rate_Hz  # [..., T, F]
    mag = np.swapaxes(mag, -1, -2)  # [..., F, T]
    mag[bad] = np.nan
    times = t0_s + (starts + 0.5 * (nw - 1)) / sample_rate_Hz
    freq = np.asarray(np.fft.rfftfreq(n_fft, 1.0 / sample_rate_Hz), np.float64)
    return Stft(np.asarray(times, np.float64), freq, np.asarray(mag, np.float64))


def ridge_frequency(
    s: Stft,
    f_min_Hz: float = 0.0,
    f_max_Hz: float = math.inf,
    rel_threshold: float = 0.05,
) -> NDArray[np.float64]:
    """Peak frequency (Hz) of every frame ``[..., T]`` within ``[f_min_Hz, f_max_Hz]``.

    NaN for frames whose peak is below ``rel_threshold`` times the record's largest peak (the
    silent frames), and for unmeasured records.
    """
    sel = (s.freq_Hz >= f_min_Hz) & (s.freq_Hz <= f_max_Hz)
    m = s.magnitude[..., sel, :]
    f = s.freq_Hz[sel]
    if f.size == 0:
        return np.full(s.magnitude.shape[:-2] + s.magnitude.shape[-1:], np.nan)
    filled = np.where(np.isfinite(m), m, -1.0)
    k = np.argmax(filled, axis=-2)  # [..., T]
    peak = np.take_along_axis(filled, k[..., None, :], axis=-2)[..., 0, :]
    top = np.max(peak, axis=-1, keepdims=True)
    out = f[k].astype(np.float64)
    return np.where((peak >= rel_threshold * top) & (peak > 0), out, np.nan)
