"""Bending of one cylinder touched at its centre: Timoshenko (or Euler-Bernoulli) beam theory.

A free-free cylinder loaded at its centre only moves in its symmetric bending modes, and by
symmetry each half is a cantilever of length ``l = L/2`` whose root (the centre) translates with
zero slope. The exact apparent mass of one half at the root, for a root displacement ``u e^{iwt}``,
is obtained here from the 4x4 transfer matrix of the beam equations (no mesh):

    state y = [w/l, psi, M l/EI, V l^2/EI] along xi = x/l in [0, 1],
    dy/dxi = A(lambda) y,
    A = [[0, 1, 0, s], [0, 0, 1, 0], [0, -lambda r, 0, -1], [-lambda, 0, 0, 0]],
    lambda = rho A w^2 l^4 / (E I),  s = E I / (kappa G A l^2) (shear),
    r = I / (A l^2) (rotary inertia).

Root: w = l (unit scaled displacement), psi = 0; tip: M = V = 0. The root shear gives the apparent
mass ``M_half(w) = m_half * V_hat(0) / lambda``; its poles are the centre-clamped (cantilever)
frequencies ``w_j`` and its residues the effective modal masses ``m_j``, so
``M(w) = sum_j m_j w_j^2 / (w_j^2 - w^2)`` exactly. Euler-Bernoulli is ``s = r = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm
from scipy.optimize import brentq

from sim_backend.dem.material import Material

__all__ = [
    "BeamModes",
    "apparent_mass_kg",
    "beam_modes",
    "section_parameters",
]


@dataclass(frozen=True)
class BeamModes:
    """Symmetric bending modes of one whole cylinder seen at its centre.

    Attributes
    ----------
    mass_kg: total mass m of the cylinder.
    omega_rad_s: [J] centre-clamped natural angular frequencies w_j (rad/s), ascending.
    modal_mass_kg: [J] effective modal masses m_j of the whole cylinder (kg).
    residual_mass_kg: m0 = m - sum_j m_j (kg).
    """

    mass_kg: float
    omega_rad_s: NDArray[np.float64]
    modal_mass_kg: NDArray[np.float64]
    residual_mass_kg: float

    @property
    def stiffness_N_per_m(self) -> NDArray[np.float64]:
        """[J] resonator stiffnesses k_j = m_j w_j^2 (N/m)."""
        return self.modal_mass_kg * self.omega_rad_s**2


def section_parameters(
    length_m: float, diameter_m: float, material: Material, theory: str = "timoshenko"
) -> tuple[float, float, float, float]:
    """Scaled beam parameters of one half-cylinder.

    Returns ``(m_half_kg, s, r, lambda_per_omega2)`` where ``lambda = lambda_per_omega2 * w^2``.
    ``theory``: ``"timoshenko"`` or ``"euler-bernoulli"``.
    """
    if theory not in ("timoshenko", "euler-bernoulli"):
        raise ValueError(f"theory must be 'timoshenko' or 'euler-bernoulli', got {theory!r}")
    half = 0.5 * length_m
    area = math.pi * diameter_m**2 / 4.0
    inertia = math.pi * diameter_m**4 / 64.0
    E = material.youngs_modulus_Pa
    rho = material.density_kg_per_m3
    if theory == "timoshenko":
        s = E * inertia / (material.shear_coefficient * material.shear_modulus_Pa * area * half**2)
        r = inertia / (area * half**2)
    else:
        s = 0.0
        r = 0.0
    return rho * area * half, s, r, rho * area * half**4 / (E * inertia)


def _transfer(lam: float, s: float, r: float) -> NDArray[np.float64]:
    a = np.array(
        [
            [0.0, 1.0, 0.0, s],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, -lam * r, 0.0, -1.0],
            [-lam, 0.0, 0.0, 0.0],
        ]
    )
    return np.asarray(expm(a), dtype=np.float64)


def _det_and_numer(lam: float, s: float, r: float) -> tuple[float, float]:
    """det of the tip block (zero at the clamped-root frequencies) and the numerator of V_hat(0)."""
    t = _transfer(lam, s, r)
    det = t[2, 2] * t[3, 3] - t[2, 3] * t[3, 2]
    # T[2:4,2:4] @ [M0, V0] = -T[2:4,0]  ->  V0 = numer / det (Cramer)
    numer = -(t[2, 2] * t[3, 0] - t[3, 2] * t[2, 0])
    return det, numer


def _v0(lam: float, s: float, r: float) -> float:
    det, numer = _det_and_numer(lam, s, r)
    return numer / det


def apparent_mass_kg(
    omega_rad_s: float,
    length_m: float,
    diameter_m: float,
    material: Material,
    theory: str = "timoshenko",
) -> float:
    """Exact (continuum) apparent mass of the whole cylinder at its centre, M(w) in kg.

    Positive below the first centre-clamped frequency, infinite at each w_j, zero at the
    free-free symmetric bending frequencies.
    """
    m_half, s, r, lam_w2 = section_parameters(length_m, diameter_m, material, theory)
    lam = lam_w2 * omega_rad_s**2
    if lam < 1e-9:
        return 2.0 * m_half
    return 2.0 * m_half * _v0(lam, s, r) / lam


@lru_cache(maxsize=4096)
def _modes_cached(
    length_m: float, diameter_m: float, material: Material, n_modes: int, theory: str
) -> BeamModes:
    m_half, s, r, lam_w2 = section_parameters(length_m, diameter_m, material, theory)
    roots: list[float] = []
    # bracket the roots of det(lambda) in beta = lambda^(1/4); EB roots are spaced ~pi in beta
    step = 0.02
    beta_prev = 0.5
    d_prev = _det_and_numer(beta_prev**4, s, r)[0]
    beta = beta_prev
    while len(roots) < n_modes:
        beta = beta_prev + step
        d = _det_and_numer(beta**4, s, r)[0]
        if d_prev == 0.0 or (d_prev < 0.0) != (d < 0.0):
            b = brentq(
                lambda x: _det_and_numer(x**4, s, r)[0], beta_prev, beta, xtol=1e-14, rtol=1e-14
            )
            roots.append(float(b))
        beta_prev, d_prev = beta, d
        if beta > 200.0:
            raise ValueError(f"could not find {n_modes} bending modes (found {len(roots)})")
    lam = np.array([b**4 for b in roots])
    fractions = np.empty(n_modes)
    for j, lj in enumerate(lam):
        h = 1e-6 * lj
        ddet = (_det_and_numer(lj + h, s, r)[0] - _det_and_numer(lj - h, s, r)[0]) / (2.0 * h)
        numer = _det_and_numer(lj, s, r)[1]
        fractions[j] = -numer / (ddet * lj**2)
    mass = 2.0 * m_half
    omega = np.sqrt(lam / lam_w2)
    modal = fractions * mass
    return BeamModes(mass, omega, modal, float(mass - modal.sum()))


def beam_modes(
    length_m: float,
    diameter_m: float,
    material: Material,
    n_modes: int = 3,
    theory: str = "timoshenko",
) -> BeamModes:
    """Centre-clamped symmetric modes of a cylinder (length, diameter in m), cached.

    Returns w_j (rad/s), effective masses m_j (kg, of the whole cylinder) and the residual m0.
    """
    if n_modes < 1:
        raise ValueError(f"n_modes must be >= 1, got {n_modes}")
    return _modes_cached(float(length_m), float(diameter_m), material, int(n_modes), theory)
