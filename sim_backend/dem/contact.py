"""Hertz contact between two equal cylinders crossed at 90 degrees (sphere R = d/2 on a flat)."""

from __future__ import annotations

import math

from sim_backend.dem.material import Material

__all__ = ["hertz_beta", "linear_stiffness", "static_overlap"]


def hertz_beta(diameter_m: float, material: Material) -> float:
    """beta_c = (4/3) E* sqrt(d/2) in N/m^1.5, so that F = beta_c * delta^1.5."""
    return 4.0 / 3.0 * material.contact_modulus_Pa * math.sqrt(0.5 * diameter_m)


def static_overlap(preload_N: float, beta_c: float) -> float:
    """delta0 = (F0 / beta_c)^(2/3) in m."""
    return (preload_N / beta_c) ** (2.0 / 3.0)


def linear_stiffness(preload_N: float, beta_c: float) -> float:
    """K = (3/2) beta_c^(2/3) F0^(1/3) in N/m, the contact stiffness about the preload."""
    return 1.5 * beta_c ** (2.0 / 3.0) * preload_N ** (1.0 / 3.0)
