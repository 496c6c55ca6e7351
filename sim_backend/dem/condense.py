"""Static condensation of resonators far above a drive's band into the primary mass.

A resonator (m_j, k_j = m_j w_j^2) driven at ``w << w_j`` moves with the primary mass: its
apparent mass ``m_j w_j^2 / (w_j^2 - w^2) = m_j (1 + r^2 + r^4 + ...)``, ``r = w / w_j``, is
``m_j`` to first order, so the mode can be dropped and its mass joined to ``m0`` (this is the
beam model with fewer modes). The apparent mass of the cylinder then changes by
``m_j r^2 / (1 - r^2)`` per dropped mode. :func:`condensation_error` bounds that change relative
to the cylinder's mass over ``[0, f_max]`` (the error grows with ``w``, so ``f_max`` is the worst
case): ``eps = max_i sum_{dropped j} (m_ij / m_i) r_ij^2 / (1 - r_ij^2)``, ``r_ij = f_max/f_ij``.

The contact dashpots are kept exactly as in the full chain (they belong to the contacts, not to
the masses), so the condensed chain differs from the full one only in the dropped resonators.

:func:`drive_top_frequency_Hz` gives ``f_max`` of a drive: the top of its spectrum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.chain import Chain, build_chain
from sim_backend.dem.drive import Drive

__all__ = [
    "SPECTRUM_FLOOR",
    "CondensedChain",
    "condensation_error",
    "condense_chain",
    "drive_top_frequency_Hz",
    "modes_to_keep",
]

#: the top of a spectrum is where its amplitude falls below this fraction of the peak
#: (a Gaussian burst's spectrum at f_c + 4 sigma_f: exp(-8) = 3.4e-4)
SPECTRUM_FLOOR = math.exp(-8.0)


def drive_top_frequency_Hz(drive: Drive, n_sigma: float = 4.0) -> float:
    """Top (Hz) of the drive's spectrum, before any nonlinear harmonics.

    Burst: ``f_c + n_sigma * sigma_f`` with ``sigma_f = 1 / (2 pi sigma_t)`` the spectral standard
    deviation of the Gaussian envelope (``n_sigma = 4``: amplitude down to 3.4e-4 of the peak).
    Waveform: the highest frequency of its (zero-padded) spectrum above
    ``SPECTRUM_FLOOR`` times the peak.
    """
    if drive.burst is not None:
        sigma_f = 1.0 / (2.0 * math.pi * drive.burst.sigma_s)
        return drive.burst.f_center_Hz + n_sigma * sigma_f
    assert drive.waveform is not None
    samples, rate = drive.waveform
    x = np.asarray(samples, dtype=np.float64)
    n = 4 * max(x.size, 256)
    spec = np.abs(np.fft.rfft(x, n=n))
    f = np.fft.rfftfreq(n, 1.0 / rate)
    above = np.flatnonzero(spec > SPECTRUM_FLOOR * spec.max())
    return float(f[above[-1]]) if above.size else 0.0


def condensation_error(chain: Chain, keep_modes: int, f_max_Hz: float) -> float:
    """Bound on the relative apparent-mass error over ``[0, f_max_Hz]`` when only the first
    ``keep_modes`` resonators of every cylinder are kept (the others condensed into ``m0``):
    ``max_i sum_{j >= keep} (m_ij / m_i) r^2 / (1 - r^2)``, ``r = f_max / f_ij``; ``inf`` if a
    dropped mode lies at or below ``f_max`` (it cannot be condensed). Dimensionless."""
    if keep_modes >= chain.n_modes:
        return 0.0
    f_j = chain.omega_res_rad_s[:, keep_modes:] / (2.0 * math.pi)  # [N, dropped]
    r2 = (f_max_Hz / f_j) ** 2
    if np.any(r2 >= 1.0):
        return math.inf
    frac = chain.m_res_kg[:, keep_modes:] / chain.mass_kg[:, None]
    return float(np.max(np.sum(frac * r2 / (1.0 - r2), axis=1)))


def modes_to_keep(chain: Chain, f_max_Hz: float, max_error: float) -> int:
    """Fewest resonators per cylinder (>= 1) whose condensation error over ``[0, f_max_Hz]`` is at
    most ``max_error`` (dimensionless)."""
    for keep in range(1, chain.n_modes + 1):
        if condensation_error(chain, keep, f_max_Hz) <= max_error:
            return keep
    return chain.n_modes


@dataclass(frozen=True, eq=False)
class CondensedChain(Chain):
    """A :class:`Chain` whose upper resonators were condensed into ``m0``.

    Extra attributes: ``full_n_modes`` (J of the chain it came from) and ``dashpot_Ns_per_m``
    ([N+1] contact dashpots of the full chain, N s/m, kept unchanged).
    """

    full_n_modes: int
    dashpot_Ns_per_m: NDArray[np.float64]

    def contact_dashpot_Ns_per_m(self) -> NDArray[np.float64]:
        """[N+1] the full chain's contact dashpots (N s/m): condensation leaves contacts alone."""
        return self.dashpot_Ns_per_m.copy()


def condense_chain(chain: Chain, keep_modes: int) -> Chain:
    """The chain with only the first ``keep_modes`` resonators per cylinder; the masses of the
    others join ``m0`` (total masses unchanged), contacts and their dashpots unchanged.
    Returns ``chain`` itself when nothing is dropped."""
    if not 1 <= keep_modes <= chain.n_modes:
        raise ValueError(f"keep_modes must be in 1..{chain.n_modes}, got {keep_modes}")
    if keep_modes == chain.n_modes:
        return chain
    reduced = build_chain(chain.spec.model_copy(update={"n_modes": keep_modes}))
    fields = {name: getattr(reduced, name) for name in reduced.__dataclass_fields__}
    return CondensedChain(
        **fields,
        full_n_modes=chain.n_modes,
        dashpot_Ns_per_m=chain.contact_dashpot_Ns_per_m(),
    )
