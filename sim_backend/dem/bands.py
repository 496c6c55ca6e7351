"""Quasi-band edges of every cylinder: w^2 M(w) = 4 K sin^2(q/2) for its periodic chain.

Band 0 is the acoustic band [0, c1]; band b >= 1 lies between the b-th and (b+1)-th centre-clamped
frequencies, from its onset (q = 0: M(w) = 0, a free-free symmetric bending frequency) to its
cutoff (q = pi: w^2 M(w) = 4K). ``quasi_bands`` uses the DEM cell (J resonators);
``continuum_bands`` uses the exact beam apparent mass (the check).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.beam import apparent_mass_kg, beam_modes
from sim_backend.dem.chain import Chain

__all__ = ["Bands", "cell_apparent_mass_kg", "continuum_bands", "quasi_bands"]


@dataclass(frozen=True)
class Bands:
    """Per-cylinder band edges. ``onset_Hz``/``cutoff_Hz``: [N, B] in Hz; band 0 is acoustic."""

    onset_Hz: NDArray[np.float64]
    cutoff_Hz: NDArray[np.float64]

    @property
    def n_bands(self) -> int:
        """B."""
        return int(self.onset_Hz.shape[1])


def cell_apparent_mass_kg(chain: Chain, i: int, omega_rad_s: float) -> float:
    """DEM apparent mass of cylinder index ``i`` (0-based): m0 + sum m_j w_j^2/(w_j^2 - w^2)."""
    wj2 = chain.omega_res_rad_s[i] ** 2
    return float(chain.m0_kg[i] + np.sum(chain.m_res_kg[i] * wj2 / (wj2 - omega_rad_s**2)))


def _beam_mass(length_m: float, chain: Chain, theory: str, w: float) -> float:
    return apparent_mass_kg(w, length_m, chain.diameter_m, chain.material, theory)


def _edges(
    mass_fn: Callable[[float], float], poles: NDArray[np.float64], k4: float, n_bands: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    from scipy.optimize import brentq  # 0.2-1 s to import: only where bands are computed

    onset = np.zeros(n_bands)
    cutoff = np.zeros(n_bands)
    for b in range(n_bands):
        lo = 0.0 if b == 0 else float(poles[b - 1])
        hi = float(poles[b]) if b < len(poles) else (lo * 4.0 + 1.0)
        eps = 1e-9 * max(hi, 1.0)
        a = lo + eps if b > 0 else 1e-6 * hi
        z = hi - eps
        if b > 0:
            onset[b] = brentq(mass_fn, a, z, xtol=1e-12, rtol=1e-13)
        g = lambda w: w * w * mass_fn(w) - k4  # noqa: E731
        if b >= len(poles):
            while g(z) < 0.0:
                z *= 2.0
        cutoff[b] = brentq(g, a, z, xtol=1e-12, rtol=1e-13)
    return onset / (2.0 * math.pi), cutoff / (2.0 * math.pi)


def quasi_bands(chain: Chain, n_bands: int = 3) -> Bands:
    """Onset/cutoff edges (Hz) of the first ``n_bands`` bands of every cylinder (DEM cell).

    ``n_bands`` may be at most J + 1 (J resonators per cylinder).

    The cell's apparent mass is that of its (J+1)-mass block (the primary, each resonator on a
    spring ``m_j w_j^2``), so its edges are eigenfrequencies: the onsets (``M(w) = 0``) those of
    the free block, the cutoffs (``w^2 M(w) = 4K``) those of the block with its primary held by a
    spring ``4K``, one of each between consecutive poles. All cylinders in two batched symmetric
    eigenvalue calls (numpy), no root search: the root search of the apparent mass (:func:`_edges`
    with scipy's brentq, which ``continuum_bands`` still uses) imported scipy.optimize, 0.3 s of
    every ``run_protocol`` on the simulated bench; ``tests/dem/test_bands.py`` keeps it as the
    reference, which these edges equal to 1e-12.
    """
    if not 1 <= n_bands <= chain.n_modes + 1:
        raise ValueError(f"n_bands must be in 1..{chain.n_modes + 1} for J = {chain.n_modes}")
    stiff, mass = chain.block_matrices()
    s = 1.0 / np.sqrt(mass)  # [N, J+1]
    a = s[:, :, None] * stiff * s[:, None, :]  # M^-1/2 K M^-1/2
    free = np.sqrt(np.clip(np.linalg.eigvalsh(a), 0.0, None))  # 0 (rigid), then the onsets
    a[:, 0, 0] += 4.0 * chain.K_lin * s[:, 0] ** 2
    # the cutoffs; with K_lin = 0 (preload 0 N) the lowest is 0 and round-off made it -1e-9
    held = np.sqrt(np.clip(np.linalg.eigvalsh(a), 0.0, None))
    onset = free[:, :n_bands].copy()
    onset[:, 0] = 0.0
    return Bands(onset / (2.0 * math.pi), held[:, :n_bands] / (2.0 * math.pi))


def continuum_bands(chain: Chain, n_bands: int = 3) -> Bands:
    """The same edges from the exact (continuum) beam apparent mass, as a check of the cell."""
    onset = np.empty((chain.n, n_bands))
    cutoff = np.empty((chain.n, n_bands))
    theory = chain.spec.beam_theory
    for i in range(chain.n):
        L = float(chain.lengths_m[i])
        poles = beam_modes(L, chain.diameter_m, chain.material, n_bands, theory).omega_rad_s
        onset[i], cutoff[i] = _edges(
            partial(_beam_mass, L, chain, theory),
            poles,
            4.0 * chain.K_lin,
            n_bands,
        )
    return Bands(onset, cutoff)
