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

``exp(A)`` is written in closed form (``A^2`` has two double eigenvalues, so ``exp(A)`` is a cubic
in ``A`` with cosh/cos coefficients): elementwise numpy over any number of frequencies and
cylinders at once, no BLAS call (a chain's modes cost milliseconds on a loaded host, where 10^4
threaded ``expm`` calls cost a minute); the residues use a complex-step derivative of the
determinant, exact to rounding.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.material import Material

__all__ = [
    "MODES_VERSION",
    "BeamModes",
    "apparent_mass_kg",
    "beam_modes",
    "cylinder_modes",
    "section_parameters",
]


#: changes whenever the mode computation changes its results beyond rounding (cached results
#: computed from the modes, such as the converged references, are keyed by it).
#: 2: closed-form transfer matrix and complex-step residues (effective masses exact to ~1e-13;
#: version 1, expm and a difference quotient, was off by up to 4e-9, 2e-4 at a sixth mode)
MODES_VERSION = "2: closed-form transfer, complex-step residues"


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


def _cosh_sinhc(p: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``cosh(sqrt p)`` and ``sinh(sqrt p) / sqrt p`` for real ``p`` of either sign (entire
    functions of ``p``: ``cos`` and ``sin(x)/x`` of ``sqrt(-p)`` below 0, 1 and 1 at 0)."""
    if np.iscomplexobj(p):  # both are even in sqrt(p): the principal branch will do
        root_c = np.sqrt(p)
        safe_c = np.where(root_c != 0.0, root_c, 1.0)
        return np.cosh(root_c), np.where(root_c != 0.0, np.sinh(root_c) / safe_c, 1.0)
    root = np.sqrt(np.abs(p))
    safe = np.where(root > 0.0, root, 1.0)
    pos = p >= 0.0
    c = np.where(pos, np.cosh(root), np.cos(root))
    sc = np.where(pos, np.sinh(root), np.sin(root)) / safe
    return c, np.where(root > 0.0, sc, 1.0)


def _functions_of_a2(lam: Any, s: Any, r: Any) -> tuple[Any, Any, Any, Any]:
    """Coefficients of ``exp(A) = cs A^2 + cc I + ss A^3 + sc A`` (elementwise over arrays).

    ``A^2`` has the double eigenvalues ``p1,2 = mu^2``, the roots of
    ``mu^4 + lambda (r + s) mu^2 + lambda^2 r s - lambda = 0`` (distinct for lambda > 0), so
    ``exp(A) = cosh(sqrt(A^2)) + A sinh(sqrt(A^2)) / sqrt(A^2)`` and each function ``g`` of
    ``A^2`` is its Lagrange interpolant ``(g1 - g2)/(p1 - p2) A^2 + (g2 p1 - g1 p2)/(p1 - p2) I``.
    """
    half_sum = -0.5 * lam * (r + s)
    half_gap = 0.5 * np.sqrt(lam * lam * (r - s) ** 2 + 4.0 * lam)
    p1 = half_sum + half_gap
    p2 = half_sum - half_gap
    gap = p1 - p2
    c1, s1 = _cosh_sinhc(p1)
    c2, s2 = _cosh_sinhc(p2)
    cs = (c1 - c2) / gap
    cc = (c2 * p1 - c1 * p2) / gap
    ss = (s1 - s2) / gap
    sc = (s2 * p1 - s1 * p2) / gap
    return cs, cc, ss, sc


def _transfer(lam: Any, s: Any, r: Any) -> Any:
    """``exp(A(lambda))`` in closed form, ``[..., 4, 4]`` for arrays ``lam, s, r`` of one shape
    (elementwise numpy only: no BLAS call, no threads). :func:`_det_and_numer` uses only the
    rows it needs."""
    lam, s, r = np.broadcast_arrays(np.asarray(lam), np.asarray(s), np.asarray(r))
    a = np.zeros((*lam.shape, 4, 4), dtype=np.result_type(lam, s, r, np.float64))
    a[..., 0, 1] = 1.0
    a[..., 0, 3] = s
    a[..., 1, 2] = 1.0
    a[..., 2, 1] = -lam * r
    a[..., 2, 3] = -1.0
    a[..., 3, 0] = -lam
    a2 = np.einsum("...ij,...jk->...ik", a, a)
    a3 = np.einsum("...ij,...jk->...ik", a, a2)
    cs, cc, ss, sc = (c[..., None, None] for c in _functions_of_a2(lam, s, r))
    return cs * a2 + cc * np.eye(4) + ss * a3 + sc * a


def _det_and_numer(lam: Any, s: Any, r: Any) -> tuple[Any, Any]:
    """det of the tip block (zero at the clamped-root frequencies) and the numerator of V_hat(0),
    elementwise over arrays ``lam, s, r`` (real, or complex ``lam`` for a complex step).

    Rows 2 and 3 of ``A^2`` are ``[lam, 0, -lam r, 0]``, ``[0, -lam, 0, -lam s]`` and of ``A^3``
    ``[0, lam + lam^2 r^2, 0, lam (s + r)]``, ``[lam^2 s, 0, -lam, 0]``, so the entries of
    ``T = exp(A)`` needed here are written out.
    """
    cs, cc, ss, sc = _functions_of_a2(lam, s, r)
    t20 = cs * lam
    t22 = cc - cs * lam * r
    t23 = ss * lam * (s + r) - sc
    t30 = ss * lam * lam * s - sc * lam
    t32 = -ss * lam
    t33 = cc - cs * lam * s
    det = t22 * t33 - t23 * t32
    # T[2:4,2:4] @ [M0, V0] = -T[2:4,0]  ->  V0 = numer / det (Cramer)
    numer = -(t22 * t30 - t32 * t20)
    return det, numer


def _v0(lam: float, s: float, r: float) -> float:
    det, numer = _det_and_numer(lam, s, r)
    return float(numer / det)


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


#: the scan for the roots of det(lambda) in beta = lambda^(1/4) (EB roots are spaced ~pi in
#: beta): grid start and spacing, and the largest beta searched
_BETA_START = 0.5
_BETA_STEP = 0.02
_BETA_MAX = 200.0
_BISECTIONS = 60


def _clamped_roots(
    s: NDArray[np.float64], r: NDArray[np.float64], n_modes: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The first ``n_modes`` scaled clamped-root eigenvalues ``lambda_j`` ``[n, J]`` of ``n``
    half-beams (``s, r``: [n]) and their effective-mass fractions ``[n, J]``.

    Sign changes of det on the beta grid bracket the roots; all brackets are bisected together
    to the last bit of beta (the grid and the result are those of a scalar scan with brentq at
    xtol = rtol = 1e-14, to rounding); the residue of ``V_hat(0)`` at each root by a central
    derivative of det by a complex step.
    """
    n = s.size
    top = _BETA_START + (n_modes + 2) * math.pi
    while True:
        beta = _BETA_START + _BETA_STEP * np.arange(math.ceil((top - _BETA_START) / _BETA_STEP) + 1)
        det = _det_and_numer(beta[None, :] ** 4, s[:, None], r[:, None])[0]
        neg = det < 0.0
        change = (neg[:, :-1] != neg[:, 1:]) | (det[:, :-1] == 0.0)
        found = change.sum(axis=1)
        if found.min() >= n_modes or top >= _BETA_MAX:
            break
        top = min(2.0 * top, _BETA_MAX)
    if found.min() < n_modes:
        raise ValueError(f"could not find {n_modes} bending modes (found {int(found.min())})")
    rows, cols = np.nonzero(change)
    keep = np.concatenate([np.arange(c) < n_modes for c in found])  # first J of each row
    rows, cols = rows[keep], cols[keep]
    lo = beta[cols].copy()
    hi = beta[cols + 1].copy()
    ss, rr = s[rows], r[rows]
    d_lo = det[rows, cols]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        d_mid = _det_and_numer(mid**4, ss, rr)[0]
        left = (d_lo == 0.0) | ((d_lo < 0.0) != (d_mid < 0.0))
        hi = np.where(left, mid, hi)
        lo = np.where(left, lo, mid)
        d_lo = np.where(left, d_lo, d_mid)
    root = np.where(d_lo == 0.0, lo, 0.5 * (lo + hi))
    lam = root**4
    # d det / d lambda by a complex step (det is analytic in lambda): exact to rounding, where a
    # real difference quotient loses ~1e-8 (up to 1e-4 at the sixth mode) to cancellation
    h = 1e-30 * lam
    ddet = _det_and_numer(lam + 1j * h, ss, rr)[0].imag / h
    numer = _det_and_numer(lam, ss, rr)[1]
    fractions = -numer / (ddet * lam**2)
    return lam.reshape(n, n_modes), fractions.reshape(n, n_modes)


def cylinder_modes(
    lengths_m: Sequence[float],
    diameter_m: float,
    materials: Sequence[Material],
    n_modes: int = 3,
    theory: str = "timoshenko",
) -> list[BeamModes]:
    """:func:`beam_modes` of many cylinders at once (``lengths_m[i]`` of ``materials[i]``), in one
    vectorised root search: a few milliseconds for a chain, no BLAS call."""
    if n_modes < 1:
        raise ValueError(f"n_modes must be >= 1, got {n_modes}")
    if len(lengths_m) != len(materials):
        raise ValueError("cylinder_modes: one material per length")
    if len(lengths_m) == 0:
        return []
    params = [
        section_parameters(float(L), diameter_m, mat, theory)
        for L, mat in zip(lengths_m, materials, strict=True)
    ]
    m_half, s, r, lam_w2 = (np.array(col, dtype=np.float64) for col in zip(*params, strict=True))
    lam, fractions = _clamped_roots(s, r, int(n_modes))
    out = []
    for i in range(len(params)):
        mass = 2.0 * float(m_half[i])
        modal = fractions[i] * mass
        omega = np.sqrt(lam[i] / lam_w2[i])
        out.append(BeamModes(mass, omega, modal, float(mass - modal.sum())))
    return out


@lru_cache(maxsize=4096)
def _modes_cached(
    length_m: float, diameter_m: float, material: Material, n_modes: int, theory: str
) -> BeamModes:
    return cylinder_modes([length_m], diameter_m, [material], n_modes, theory)[0]


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
