"""The Gaussian-modulated sine burst: one definition for the generator and the simulator.

The function generator uploads :func:`burst_waveform` sampled at its arbitrary-waveform rate,
and the DEM drives the chain with the same function sampled at its own step, so the bench and
the simulation see the same pulse.

Shape, for ``0 <= t <= T`` with ``T = duration_s`` and ``t0 = T/2``::

    w(t) = g(t) * cos(2 pi f_c (t - t0))
    g(t) = (exp(-(t - t0)^2 / (2 sigma^2)) - e_end) / (1 - e_end),   e_end = exp(-T^2 / (8 sigma^2))

so the envelope is exactly zero at both ends (first and last samples are 0) and peaks at 1.
With ``cycles = n`` the burst spans ``T = n / f_c`` and ``sigma = T / 6`` (the window holds
+/-3 sigma). With ``width_s = sigma`` given instead, ``T = 6 sigma``. A Gaussian sigma in
frequency ``sigma_f`` is the same burst with ``width_s = 1 / (2 pi sigma_f)``
(:func:`width_from_sigma_f`).

The default burst is :data:`NARROWBAND_CYCLES` = 21 cycles (sigma = 3.5 carrier periods, a
spectral sigma of ``f_c / 22``: +-0.41 kHz at 8.92 kHz, +-0.30 kHz at 6.63 kHz). A 5-cycle burst
(:data:`NAMED_BURSTS` ``"five_cycle"``) spreads over about +-1.5 kHz, and its tail near 8.0 kHz,
where the bands of the chain's end cylinders nearly meet, passes through the chain linearly.

The normalised waveform peaks at exactly 1 at ``t0`` (cosine carrier), so an amplitude is the
burst's peak value; amplitudes are applied by whoever plays it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "NAMED_BURSTS",
    "NARROWBAND_CYCLES",
    "SIGMAS_PER_HALF_WINDOW",
    "Burst",
    "burst_samples",
    "burst_waveform",
    "width_from_sigma_f",
]

#: the window spans +/- this many Gaussian sigmas around its centre
SIGMAS_PER_HALF_WINDOW = 3.0

#: the default burst length in carrier cycles: sigma = 3.5 carrier periods, narrow enough in
#: frequency (sigma_f = f_c / 22) that the paper's linear regime shows on the default chain
NARROWBAND_CYCLES = 21.0

#: bursts by name, as cycles in the window: ``narrowband`` (the default) and ``five_cycle``
#: (broadband, +-1.5 kHz; kept for labs that use it)
NAMED_BURSTS: dict[str, float] = {"narrowband": NARROWBAND_CYCLES, "five_cycle": 5.0}


def width_from_sigma_f(sigma_f_Hz: float) -> float:
    """Gaussian sigma in time (s) of a burst whose spectral Gaussian sigma is ``sigma_f_Hz``."""
    if not (math.isfinite(sigma_f_Hz) and sigma_f_Hz > 0):
        raise ValueError(f"burst spectral sigma must be > 0 Hz, got {sigma_f_Hz!r}")
    return 1.0 / (2.0 * math.pi * sigma_f_Hz)


@dataclass(frozen=True)
class Burst:
    """A Gaussian-modulated sine burst (shape only; amplitude is set by the player).

    Attributes
    ----------
    f_center_Hz:
        Carrier (centre) frequency in Hz, > 0.
    cycles:
        Number of carrier cycles in the window, or ``None`` when ``width_s`` is given.
    width_s:
        Gaussian standard deviation of the envelope in s, or ``None`` when ``cycles`` is given.
    """

    f_center_Hz: float
    cycles: float | None = NARROWBAND_CYCLES
    width_s: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.f_center_Hz) and self.f_center_Hz > 0):
            raise ValueError(f"burst centre frequency must be > 0 Hz, got {self.f_center_Hz!r}")
        if (self.cycles is None) == (self.width_s is None):
            raise ValueError("give exactly one of burst cycles or width")
        if self.cycles is not None and not (math.isfinite(self.cycles) and self.cycles > 0):
            raise ValueError(f"burst cycles must be > 0, got {self.cycles!r}")
        if self.width_s is not None and not (math.isfinite(self.width_s) and self.width_s > 0):
            raise ValueError(f"burst width must be > 0 s, got {self.width_s!r}")

    @property
    def duration_s(self) -> float:
        """Length of the burst window T in s."""
        if self.cycles is not None:
            return self.cycles / self.f_center_Hz
        assert self.width_s is not None
        return 2.0 * SIGMAS_PER_HALF_WINDOW * self.width_s

    @property
    def sigma_f_Hz(self) -> float:
        """Gaussian standard deviation of the spectrum in Hz, ``1 / (2 pi sigma_s)``."""
        return 1.0 / (2.0 * math.pi * self.sigma_s)

    @property
    def sigma_s(self) -> float:
        """Gaussian standard deviation of the envelope in s."""
        return self.duration_s / (2.0 * SIGMAS_PER_HALF_WINDOW)

    def at(self, t_s: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """Normalised waveform at times ``t_s`` (s, from the burst start); 0 outside [0, T]."""
        return burst_waveform(np.asarray(t_s, dtype=np.float64), self)


def burst_waveform(t_s: NDArray[np.float64], burst: Burst) -> NDArray[np.float64]:
    """Normalised burst at times ``t_s`` (s from the start of the window), shape of ``t_s``.

    Zero outside ``[0, T]`` and exactly zero at ``t = 0`` and ``t = T``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    T = burst.duration_s
    sigma = burst.sigma_s
    t0 = 0.5 * T
    e_end = math.exp(-(t0**2) / (2.0 * sigma**2))
    env = (np.exp(-((t - t0) ** 2) / (2.0 * sigma**2)) - e_end) / (1.0 - e_end)
    w = env * np.cos(2.0 * math.pi * burst.f_center_Hz * (t - t0))
    inside = (t > 0.0) & (t < T)
    return np.where(inside, w, 0.0)


def burst_samples(burst: Burst, sample_rate_Hz: float) -> NDArray[np.float64]:
    """The burst sampled at ``sample_rate_Hz`` over its window, first and last samples 0.

    Returns an array of ``n = round(T * rate) + 1`` samples (at least 8), values in [-1, 1].
    """
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample rate must be > 0, got {sample_rate_Hz!r}")
    n = max(8, round(burst.duration_s * sample_rate_Hz) + 1)
    t = np.arange(n, dtype=np.float64) * (burst.duration_s / (n - 1))
    w = burst_waveform(t, burst)
    w[0] = 0.0
    w[-1] = 0.0
    return w
