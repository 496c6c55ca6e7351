"""Reading the quasi-band edges stored with a run (``/chain``), and what they predict.

``ChainInfo.onset_Hz`` and ``cutoff_Hz`` are ``[N, B]``: for cylinder ``i`` (0-based) and band
``b`` the band is ``[onset_Hz[i, b], cutoff_Hz[i, b]]``. The physics notes number the bands
``[0, c1]``, gap, ``[f1, c2]`` (the first local-resonance band), gap, ... The band that matters
for BiAFC is the first local-resonance band; :func:`resonance_band_index` finds it as the first
band whose onset is above 0 Hz for every cylinder (so a file that stores the acoustic band
``[0, c1]`` in column 0 and one that starts at ``[f1, c2]`` are both read right).

Directions: LTR enters at cylinder #1 and its far end is #N; RTL enters at #N, far end #1.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from protocols.runfile import ChainInfo

__all__ = [
    "asymmetry_factor",
    "band_edges",
    "entry_cylinder",
    "expected_output_Hz",
    "far_cylinder",
    "linear_limit_cylinder",
    "peak_search_range_Hz",
    "resonance_band_index",
    "signal_band_Hz",
]

#: the signal band reaches this fraction of f_in beyond the input and the expected edge (the
#: converted line overshoots the far cylinder's edge: 7.16 kHz at 4 um for the 8.03 kHz LTR
#: cutoff of the default chain, 10 % of f_in)
SIGNAL_BAND_MARGIN = 0.15
#: ... and at least this many of the burst's spectral sigmas
SIGNAL_BAND_SIGMAS = 3.0


def _check_direction(direction: str) -> None:
    if direction not in ("ltr", "rtl"):
        raise ValueError(f"direction must be 'ltr' or 'rtl', got {direction!r}")


def entry_cylinder(direction: str, n_cylinders: int) -> int:
    """1-based number of the cylinder the drive enters: #1 for LTR, #N for RTL."""
    _check_direction(direction)
    return 1 if direction == "ltr" else n_cylinders


def far_cylinder(direction: str, n_cylinders: int) -> int:
    """1-based number of the far (output) cylinder: #N for LTR, #1 for RTL."""
    _check_direction(direction)
    return n_cylinders if direction == "ltr" else 1


def resonance_band_index(chain: ChainInfo) -> int:
    """Column of ``onset_Hz``/``cutoff_Hz`` holding the first local-resonance band.

    The first band whose onset is > 0 Hz at every cylinder (and below its cutoff).
    Raises ValueError when the file holds no such band.
    """
    onset = np.atleast_2d(chain.onset_Hz)
    cutoff = np.atleast_2d(chain.cutoff_Hz)
    for b in range(onset.shape[1]):
        o, c = onset[:, b], cutoff[:, b]
        if np.all(np.isfinite(o)) and np.all(o > 0) and np.all(c > o):
            return b
    raise ValueError(
        "the run file's /chain holds no local-resonance band with a non-zero onset (a chain "
        "without preload has none): what needs its band edges cannot be drawn"
    )


def band_edges(
    chain: ChainInfo, band_index: int | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(onset_Hz [N], cutoff_Hz [N])`` of one band (default: the first local-resonance band)."""
    b = resonance_band_index(chain) if band_index is None else band_index
    onset = np.atleast_2d(chain.onset_Hz)
    cutoff = np.atleast_2d(chain.cutoff_Hz)
    if not 0 <= b < onset.shape[1]:
        raise ValueError(f"band index {b} out of range: the file holds {onset.shape[1]} bands")
    return onset[:, b].astype(np.float64), cutoff[:, b].astype(np.float64)


def expected_output_Hz(
    f_in_Hz: float, direction: str, onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]
) -> float:
    """Where the converted frequency is expected to saturate: a band edge of the far cylinder.

    If ``f_in_Hz`` lies above the far cylinder's band, its cutoff (down-conversion, LTR in the
    paper); if below, its onset (up-conversion, RTL); inside the band, ``f_in_Hz`` itself.
    """
    n = len(onset_Hz)
    k = far_cylinder(direction, n) - 1
    if not (math.isfinite(onset_Hz[k]) and math.isfinite(cutoff_Hz[k])):
        return math.nan  # no band (a chain without preload): no edge to head for
    if f_in_Hz > cutoff_Hz[k]:
        return float(cutoff_Hz[k])
    if f_in_Hz < onset_Hz[k]:
        return float(onset_Hz[k])
    return float(f_in_Hz)


def linear_limit_cylinder(
    f_in_Hz: float, direction: str, onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]
) -> int | None:
    """1-based number of the first cylinder, walking from the entry, whose band excludes f_in.

    This is the linear limit of the paper's Fig. 3: in the linear regime the packet turns back
    before it. ``None`` when ``f_in_Hz`` lies in every cylinder's band.
    """
    n = len(onset_Hz)
    order = range(n) if entry_cylinder(direction, n) == 1 else range(n - 1, -1, -1)
    for i in order:
        if not onset_Hz[i] <= f_in_Hz <= cutoff_Hz[i]:
            return i + 1
    return None


def asymmetry_factor(onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]) -> float:
    """The paper's ``alpha = (alpha_c + alpha_s) / 2`` (dimensionless).

    ``alpha_c = |f_c,1 - f_c,N| / f_c,cen`` and ``alpha_s = |f_s,1 - f_s,N| / f_s,cen`` with
    cutoff (c) and onset (s) edges of the first, central and last cylinders.
    """
    n = len(onset_Hz)
    if n < 2:
        return 0.0
    mid = (n - 1) / 2.0

    def centre(edge: NDArray[np.float64]) -> float:
        return float(np.interp(mid, np.arange(n), edge))

    a_c = abs(cutoff_Hz[0] - cutoff_Hz[-1]) / centre(cutoff_Hz)
    a_s = abs(onset_Hz[0] - onset_Hz[-1]) / centre(onset_Hz)
    return float(0.5 * (a_c + a_s))


def peak_search_range_Hz(
    f_in_Hz: float, onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]
) -> tuple[float, float]:
    """Frequency range (Hz) in which output peaks are looked for.

    From 0.7 times the lower of ``f_in_Hz`` and the lowest onset to 1.3 times the higher of
    ``f_in_Hz`` and the highest cutoff: the band and its neighbourhood, leaving out the
    low-frequency drift of opened contacts and the harmonics.
    """
    if not (np.any(np.isfinite(onset_Hz)) and np.any(np.isfinite(cutoff_Hz))):  # no band
        return 0.5 * f_in_Hz, 1.5 * f_in_Hz
    lo = min(f_in_Hz, float(np.nanmin(onset_Hz)))
    hi = max(f_in_Hz, float(np.nanmax(cutoff_Hz)))
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return 0.5 * f_in_Hz, 1.5 * f_in_Hz
    return 0.7 * lo, 1.3 * hi


def signal_band_Hz(
    f_in_Hz: float,
    direction: str,
    onset_Hz: NDArray[np.float64],
    cutoff_Hz: NDArray[np.float64],
    sigma_f_Hz: float | None = None,
) -> tuple[float, float]:
    """Frequency range (Hz) where the far end's signal can be: the burst's band and the
    converted band, from the lower to the higher of ``f_in_Hz`` and the expected output
    (:func:`expected_output_Hz`), widened on both sides by the larger of
    :data:`SIGNAL_BAND_SIGMAS` burst sigmas ``sigma_f_Hz`` and :data:`SIGNAL_BAND_MARGIN` x
    ``f_in_Hz``; inside :func:`peak_search_range_Hz`, which it is when the chain has no band.
    The noise floor is decided over it (:mod:`analysis.noise_floor`)."""
    search = peak_search_range_Hz(f_in_Hz, onset_Hz, cutoff_Hz)
    if not (np.any(np.isfinite(onset_Hz)) and np.any(np.isfinite(cutoff_Hz))):
        return search
    f_exp = expected_output_Hz(f_in_Hz, direction, onset_Hz, cutoff_Hz)
    if not math.isfinite(f_exp):
        return search
    sigma = sigma_f_Hz if sigma_f_Hz is not None and math.isfinite(sigma_f_Hz) else 0.0
    w = max(SIGNAL_BAND_SIGMAS * sigma, SIGNAL_BAND_MARGIN * f_in_Hz)
    lo = max(search[0], min(f_in_Hz, f_exp) - w)
    hi = min(search[1], max(f_in_Hz, f_exp) + w)
    return lo, hi
