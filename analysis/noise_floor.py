"""The noise floor of a record, from what it holds before the trigger.

Before the trigger nothing is driven, so the pre-trigger samples of a velocity record hold the
vibrometer's and the digitiser's noise only. Their mean square, over the whole record's length,
is the energy the noise alone would give (m^2/s for velocity): ``E_noise = mean(v_pre^2) * S /
rate`` for a record of ``S`` samples. A record whose energy is not at least ``RESOLVED_FACTOR``
times that holds no signal this analysis can tell from the noise: its transmission is then only
bounded from above, and its spectral peak is a noise line.

Over a band. Broadband digitiser noise spread over 0..Nyquist hides a narrowband line that
stands well above the noise in its own band, so the decision is made within the band where the
signal can be (:func:`analysis.bands.signal_band_Hz`): the record's energy in that band
(:func:`band_energy`) against the noise's (:func:`band_noise_energy`). The noise's spectral
level is measured on the pre-trigger samples over a wider band (the peak search range) and
taken as flat within it: 1 ms of pre-trigger over the search range holds about 19 degrees of
freedom (a spread of about 33 %), over the signal band alone only about 7. With fewer than
:data:`MIN_BAND_DOF` over the level band (a short pre-trigger), the decision is made over the
whole record (0..Nyquist) as before: pure noise would otherwise stand "resolved" too often.

A record without pre-trigger samples (fewer than ``MIN_PRE_SAMPLES``) has no noise estimate
(NaN), and is taken as resolved, as before; a noiseless model run has ``E_noise = 0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "MIN_BAND_DOF",
    "MIN_PRE_SAMPLES",
    "RESOLVED_FACTOR",
    "band_energy",
    "band_noise_energy",
    "noise_energy",
    "resolved",
]

#: a record counts as resolved when its energy is at least this many times the noise's
#: (its signal's energy then at least 3x the noise's: an rms signal-to-noise ratio of 1.7)
RESOLVED_FACTOR = 4.0
#: fewest pre-trigger samples for a noise estimate (its relative spread is then below 40 %)
MIN_PRE_SAMPLES = 16
#: fewest degrees of freedom (``2 W T_pre``: the level band's width times the pre-trigger's
#: length, twice) for a noise estimate over a band; with fewer, pure noise stood "resolved" in
#: 3-18 % of records (0.05-0.3 ms of pre-trigger at 200-500 kS/s; a reviewer's Monte Carlo),
#: and the decision falls back to the whole record (:func:`band_dof`)
MIN_BAND_DOF = 16.0


def noise_energy(
    records: ArrayLike, time_s: ArrayLike, sample_rate_Hz: float
) -> NDArray[np.float64]:
    """Energy the noise alone would give over each whole record: ``records [..., S]`` (m/s),
    ``time_s [S]`` (s, the trigger at 0); returns ``[...]`` in m^2/s. NaN where the record is
    not measured or has fewer than :data:`MIN_PRE_SAMPLES` samples before the trigger."""
    x = np.asarray(records, dtype=np.float64)
    t = np.asarray(time_s, dtype=np.float64)
    pre = t < 0
    if np.count_nonzero(pre) < MIN_PRE_SAMPLES:
        return np.full(x.shape[:-1], np.nan)
    with np.errstate(invalid="ignore"):
        mean_sq = np.mean(x[..., pre] ** 2, axis=-1)
    return np.asarray(mean_sq * x.shape[-1] / sample_rate_Hz, dtype=np.float64)


def band_energy(
    records: ArrayLike, sample_rate_Hz: float, band_Hz: tuple[float, float], pad: int = 1
) -> NDArray[np.float64]:
    """Energy of each record ``[..., S]`` (m/s) within ``band_Hz`` (Hz, both ends included):
    ``2 / (M rate) * sum |FFT_k|^2`` over the bins in the band of the record zero-padded to
    ``M = pad * S`` samples, Parseval's share of ``integral v^2 dt`` (m^2/s); ``[...]``, NaN
    where the record holds NaN. A short record (the pre-trigger) is padded so that the band's
    width, not its count of coarse bins, sets its share."""
    x = np.asarray(records, dtype=np.float64)
    m = max(1, pad) * x.shape[-1]
    spec = np.fft.rfft(x, n=m, axis=-1)
    f = np.fft.rfftfreq(m, 1.0 / sample_rate_Hz)
    inside = (f >= band_Hz[0]) & (f <= band_Hz[1])
    power = np.sum(np.abs(spec[..., inside]) ** 2, axis=-1)
    return np.asarray(2.0 * power / (m * sample_rate_Hz), dtype=np.float64)


def band_noise_energy(
    records: ArrayLike,
    time_s: ArrayLike,
    sample_rate_Hz: float,
    band_Hz: tuple[float, float],
    level_band_Hz: tuple[float, float] | None = None,
) -> NDArray[np.float64]:
    """Energy the noise alone would give over each whole record within ``band_Hz``: the
    pre-trigger samples' energy within ``level_band_Hz`` (default ``band_Hz``; it should hold
    the band), scaled to the band's width (the noise taken as flat within the level band) and
    to the record's length. ``records [..., S]`` (m/s), ``time_s [S]`` (s, the trigger at 0);
    returns ``[...]`` in m^2/s, NaN as :func:`noise_energy`."""
    x = np.asarray(records, dtype=np.float64)
    t = np.asarray(time_s, dtype=np.float64)
    pre = t < 0
    n_pre = int(np.count_nonzero(pre))
    if n_pre < MIN_PRE_SAMPLES:
        return np.full(x.shape[:-1], np.nan)
    level = band_Hz if level_band_Hz is None else level_band_Hz
    nyquist = sample_rate_Hz / 2.0

    def width(b: tuple[float, float]) -> float:
        return max(0.0, min(b[1], nyquist) - max(b[0], 0.0))

    if width(level) <= 0:
        return np.full(x.shape[:-1], np.nan)
    # the pre-trigger's mean removed: an offset (a DC bias of the decoder or the digitiser)
    # on so short a stretch leaks into the band and had read as noise there (5 sigma of
    # offset took a perfect model's noise reference from 0.17 to 0.96; a reviewer)
    x_pre = x[..., pre]
    with np.errstate(invalid="ignore"):
        x_pre = x_pre - np.mean(x_pre, axis=-1, keepdims=True)
    e_pre = band_energy(x_pre, sample_rate_Hz, level, pad=8)
    scale = (x.shape[-1] / n_pre) * (width(band_Hz) / width(level))
    return np.asarray(e_pre * scale, dtype=np.float64)


def band_dof(time_s: ArrayLike, sample_rate_Hz: float, band_Hz: tuple[float, float]) -> float:
    """Degrees of freedom of a pre-trigger noise estimate over ``band_Hz`` (Hz): ``2 W n_pre /
    rate`` for ``n_pre`` samples before the trigger (``time_s [S]``, s) and the band's width
    ``W`` up to the Nyquist frequency. Below :data:`MIN_BAND_DOF` the band's noise is not known
    well enough to set a record against it."""
    n_pre = int(np.count_nonzero(np.asarray(time_s) < 0))
    width = max(0.0, min(band_Hz[1], sample_rate_Hz / 2.0) - max(band_Hz[0], 0.0))
    return 2.0 * width * n_pre / sample_rate_Hz


def resolved(energy: ArrayLike, noise: ArrayLike) -> NDArray[np.bool_]:
    """``[...]``: True where a record's ``energy`` stands above its ``noise`` energy (both
    m^2/s and over the same band: :func:`band_energy` and :func:`band_noise_energy`, or the
    whole record's :func:`analysis.transmission.signal_energy` and :func:`noise_energy`), or where
    the noise is not known; False where it does not or the record is not measured."""
    e = np.asarray(energy, dtype=np.float64)
    n = np.asarray(noise, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        above = e >= RESOLVED_FACTOR * n
    return np.asarray(np.isfinite(e) & (np.isnan(n) | above), dtype=np.bool_)
