"""Cell model from beam theory: Euler-Bernoulli limit, Timoshenko corrections, mass sums."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_backend.dem.beam import apparent_mass_kg, beam_modes, section_parameters
from sim_backend.dem.material import FUSED_QUARTZ, Material

L, D = 0.1, 0.0136
EB_ROOTS = (1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349)
EB_FRACTIONS = (0.6130, 0.1883, 0.0647)
FREE_FREE_SYMMETRIC = (4.7300407449, 10.9956078380)  # beta L of the free-free even modes


def _beta(omega: np.ndarray, theory: str) -> np.ndarray:
    _, _, _, lam_w2 = section_parameters(L, D, FUSED_QUARTZ, theory)
    return (lam_w2 * omega**2) ** 0.25


def test_euler_bernoulli_cantilever_roots_and_masses() -> None:
    modes = beam_modes(L, D, FUSED_QUARTZ, 4, "euler-bernoulli")
    beta = _beta(modes.omega_rad_s, "euler-bernoulli")
    np.testing.assert_allclose(beta, EB_ROOTS, rtol=1e-3)
    np.testing.assert_allclose(beta, EB_ROOTS, rtol=1e-8)  # in fact to solver precision
    fractions = modes.modal_mass_kg / modes.mass_kg
    np.testing.assert_allclose(fractions[:3], EB_FRACTIONS, rtol=1e-3, atol=1e-4)
    assert modes.residual_mass_kg == pytest.approx(modes.mass_kg - modes.modal_mass_kg.sum())


def test_euler_bernoulli_free_free_onsets() -> None:
    """Zeros of the apparent mass are the free-free symmetric frequencies (L = whole length)."""
    from scipy.optimize import brentq

    E, rho = FUSED_QUARTZ.youngs_modulus_Pa, FUSED_QUARTZ.density_kg_per_m3
    A, I = math.pi * D**2 / 4, math.pi * D**4 / 64
    modes = beam_modes(L, D, FUSED_QUARTZ, 3, "euler-bernoulli").omega_rad_s
    for k, root in enumerate(FREE_FREE_SYMMETRIC):
        w = brentq(
            lambda x: apparent_mass_kg(x, L, D, FUSED_QUARTZ, "euler-bernoulli"),
            modes[k] * 1.0001,
            modes[k + 1] * 0.9999,
        )
        w_exact = root**2 / L**2 * math.sqrt(E * I / (rho * A))
        assert w == pytest.approx(w_exact, rel=1e-3)


def test_timoshenko_lowers_frequencies_and_tends_to_eb_for_slender_beams() -> None:
    stubby_t = beam_modes(L, D, FUSED_QUARTZ, 3).omega_rad_s
    stubby_eb = beam_modes(L, D, FUSED_QUARTZ, 3, "euler-bernoulli").omega_rad_s
    assert np.all(stubby_t < stubby_eb)
    assert stubby_t[2] / stubby_eb[2] < 0.95  # shear and rotary inertia matter at L/d ~ 7
    slender_t = beam_modes(2.0, D, FUSED_QUARTZ, 3).omega_rad_s
    slender_eb = beam_modes(2.0, D, FUSED_QUARTZ, 3, "euler-bernoulli").omega_rad_s
    np.testing.assert_allclose(slender_t, slender_eb, rtol=2e-3)


def test_modal_masses_sum_towards_the_total_mass() -> None:
    few = beam_modes(L, D, FUSED_QUARTZ, 3)
    many = beam_modes(L, D, FUSED_QUARTZ, 10)
    assert many.residual_mass_kg < few.residual_mass_kg
    assert 0 < many.residual_mass_kg < 0.05 * many.mass_kg
    assert many.mass_kg == pytest.approx(2200 * math.pi * D**2 / 4 * L)


def test_apparent_mass_partial_fractions() -> None:
    """M(w) = m0 + sum m_j w_j^2/(w_j^2 - w^2) with enough modes reproduces the exact M(w)."""
    modes = beam_modes(L, D, FUSED_QUARTZ, 10)
    for f in (1e3, 7e3, 15e3, 40e3):
        w = 2 * math.pi * f
        wj2 = modes.omega_rad_s**2
        dem = modes.residual_mass_kg + np.sum(modes.modal_mass_kg * wj2 / (wj2 - w**2))
        exact = apparent_mass_kg(w, L, D, FUSED_QUARTZ)
        assert dem == pytest.approx(exact, rel=2e-3, abs=1e-5 * modes.mass_kg)


def test_material_scaling_of_modes() -> None:
    stiff = Material("x4", 4 * 72e9, 2200.0, 0.17)
    base = beam_modes(L, D, FUSED_QUARTZ, 3).omega_rad_s
    np.testing.assert_allclose(beam_modes(L, D, stiff, 3).omega_rad_s, 2 * base, rtol=1e-9)
