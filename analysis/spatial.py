"""Spatial-frequency map (paper Fig. 3): the Fourier magnitude of every cylinder's velocity.

For one direction and one amplitude: ``magnitude [C, F]`` (m, see :mod:`analysis.spectra`),
the per-cylinder peak frequency ``peak_Hz [C]`` (in the search range), and the linear limit:
the first cylinder, from the entry, whose quasi-band excludes the input frequency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from analysis.spectra import amplitude_spectrum, peak_frequency

__all__ = ["SpatialFrequencyMap", "spatial_frequency_map"]


@dataclass(frozen=True)
class SpatialFrequencyMap:
    """``cylinders [C]`` (1-based), ``freq_Hz [F]``, ``magnitude [C, F]`` in m (velocity
    spectrum; NaN rows for unmeasured cylinders), ``peak_Hz [C]`` (NaN where unmeasured)."""

    cylinders: NDArray[np.int32]
    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]
    peak_Hz: NDArray[np.float64]


def spatial_frequency_map(
    velocity: ArrayLike,
    cylinders: ArrayLike,
    sample_rate_Hz: float,
    f_range_Hz: tuple[float, float],
) -> SpatialFrequencyMap:
    """Spectra of ``velocity [C, S]`` (m/s) restricted to ``f_range_Hz``, and their peaks."""
    v = np.asarray(velocity, dtype=np.float64)
    if v.ndim != 2:
        raise ValueError(f"velocity must be [C, S], got shape {v.shape}")
    spec = amplitude_spectrum(v, sample_rate_Hz).band(*f_range_Hz)
    peaks = peak_frequency(spec)
    return SpatialFrequencyMap(
        np.asarray(cylinders, dtype=np.int32), spec.freq_Hz, spec.magnitude, peaks
    )
