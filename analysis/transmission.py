"""Energy and spectral transmission between two points of the chain.

The energy of a velocity record is ``E = integral v(t)^2 dt`` in m^2/s (proportional to the
kinetic energy that passed, for a given mass). The energy transmission from a near cylinder to
a far cylinder is ``E_far / E_near`` (dimensionless); the spectral transmission is
``|V_far(f)| / |V_near(f)|`` on a common frequency grid (dimensionless), taken only where the
near spectrum holds at least ``floor`` of its peak (NaN elsewhere, to avoid dividing noise by
noise).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from analysis.spectra import Spectrum

__all__ = ["energy_transmission", "signal_energy", "spectral_transmission"]


def signal_energy(signal: ArrayLike, sample_rate_Hz: float) -> NDArray[np.float64]:
    """``integral x(t)^2 dt`` along the last axis of ``signal [..., S]``.

    Unit: (signal unit)^2 * s (m^2/s for velocity). NaN for records holding NaN. Shape ``[...]``.
    """
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample rate must be > 0 Hz, got {sample_rate_Hz!r}")
    x = np.asarray(signal, dtype=np.float64)
    return np.asarray(np.sum(x * x, axis=-1) / sample_rate_Hz, dtype=np.float64)


def energy_transmission(
    near: ArrayLike, far: ArrayLike, sample_rate_Hz: float
) -> NDArray[np.float64]:
    """``E_far / E_near`` for records ``[..., S]`` (dimensionless, shape ``[...]``).

    NaN where either record is not measured or the near record carries no energy.
    """
    e_near = signal_energy(near, sample_rate_Hz)
    e_far = signal_energy(far, sample_rate_Hz)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = e_far / e_near
    return np.where(e_near > 0, ratio, np.nan)


def spectral_transmission(
    near: Spectrum, far: Spectrum, floor: float = 1e-3
) -> NDArray[np.float64]:
    """``|V_far(f)| / |V_near(f)|`` ``[..., F]`` (dimensionless).

    Both spectra must share one frequency grid. NaN where ``|V_near|`` is below ``floor`` times
    its own maximum.
    """
    if near.freq_Hz.shape != far.freq_Hz.shape or not np.allclose(near.freq_Hz, far.freq_Hz):
        raise ValueError("spectral transmission needs both spectra on the same frequency grid")
    n = near.magnitude
    peak = np.nanmax(n, axis=-1, keepdims=True) if n.size else n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = far.magnitude / n
    return np.where(n >= floor * peak, t, np.nan)
