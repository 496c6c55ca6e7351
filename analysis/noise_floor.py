"""The noise floor of a record, from what it holds before the trigger.

Before the trigger nothing is driven, so the pre-trigger samples of a velocity record hold the
vibrometer's and the digitiser's noise only. Their mean square, over the whole record's length,
is the energy the noise alone would give (m^2/s for velocity): ``E_noise = mean(v_pre^2) * S /
rate`` for a record of ``S`` samples. A record whose energy is not at least ``RESOLVED_FACTOR``
times that holds no signal this analysis can tell from the noise: its transmission is then only
bounded from above, and its spectral peak is a noise line.

A record without pre-trigger samples (fewer than ``MIN_PRE_SAMPLES``) has no noise estimate
(NaN), and is taken as resolved, as before; a noiseless model run has ``E_noise = 0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MIN_PRE_SAMPLES", "RESOLVED_FACTOR", "noise_energy", "resolved"]

#: a record counts as resolved when its energy is at least this many times the noise's
#: (its signal's energy then at least 3x the noise's: an rms signal-to-noise ratio of 1.7)
RESOLVED_FACTOR = 4.0
#: fewest pre-trigger samples for a noise estimate (its relative spread is then below 40 %)
MIN_PRE_SAMPLES = 16


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


def resolved(energy: ArrayLike, noise: ArrayLike) -> NDArray[np.bool_]:
    """``[...]``: True where a record's ``energy`` stands above its ``noise`` energy (both
    m^2/s, from :func:`analysis.transmission.signal_energy` and :func:`noise_energy`), or where
    the noise is not known; False where it does not or the record is not measured."""
    e = np.asarray(energy, dtype=np.float64)
    n = np.asarray(noise, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        above = e >= RESOLVED_FACTOR * n
    return np.asarray(np.isfinite(e) & (np.isnan(n) | above), dtype=np.bool_)
