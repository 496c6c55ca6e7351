"""Hertz contact between two equal cylinders crossed at an angle (90 degrees: the woodpile).

Two cylinders of radius R = d/2 whose axes cross at angle theta touch in a point. The relative
principal curvatures of the gap are A + B = 1/R and B - A = |cos theta| / R (Johnson, Contact
Mechanics, section 4.2). At 90 degrees A = B = 1/(2R): a sphere of radius R on a flat, so
beta_c = (4/3) E* sqrt(R). Otherwise the contact is an ellipse of eccentricity e fixed by the
geometry alone (B/A = ((a/b)^2 E(e) - K(e)) / (K(e) - E(e)), K and E complete elliptic integrals
of the modulus e^2), so F = beta_c delta^(3/2) still holds with a beta_c that depends on theta.
"""

from __future__ import annotations

import math

from sim_backend.dem.material import Material

__all__ = [
    "MIN_CROSSING_ANGLE_RAD",
    "hertz_beta",
    "linear_stiffness",
    "static_overlap",
]

#: crossing angles closer to parallel than this (rad) are refused: the contact tends to a line,
#: where the 3/2 law no longer holds
MIN_CROSSING_ANGLE_RAD = math.radians(10.0)


def _curvature_ratio(m: float) -> float:
    """B/A of an elliptical Hertz contact with parameter ``m = e^2`` (0 <= m < 1)."""
    from scipy.special import ellipe, ellipk

    K, E = ellipk(m), ellipe(m)
    return float((E / (1.0 - m) - K) / (K - E))


def hertz_beta(
    diameter_m: float, material: Material, crossing_angle_rad: float = 0.5 * math.pi
) -> float:
    """beta_c in N/m^1.5, so that F = beta_c * delta^1.5, for equal cylinders of diameter
    ``diameter_m`` crossed at ``crossing_angle_rad`` (default pi/2: (4/3) E* sqrt(d/2))."""
    R = 0.5 * diameter_m
    E_star = material.contact_modulus_Pa
    c = abs(math.cos(crossing_angle_rad))
    if math.sin(crossing_angle_rad) ** 2 < math.sin(MIN_CROSSING_ANGLE_RAD) ** 2 * (1 - 1e-12):
        raise ValueError(
            f"crossing angle {math.degrees(crossing_angle_rad):.3g} deg is closer to parallel "
            f"than {math.degrees(MIN_CROSSING_ANGLE_RAD):.3g} deg (line contact, not Hertzian)"
        )
    if c < 1e-9:
        return 4.0 / 3.0 * E_star * math.sqrt(R)
    # scipy.optimize and .special only here: they cost 0.2-1 s to import
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    A = 0.5 * (1.0 - c) / R
    B = 0.5 * (1.0 + c) / R
    ratio = B / A
    m = brentq(lambda x: _curvature_ratio(x) - ratio, 1e-12, 1.0 - 1e-15, xtol=1e-15)
    K, E = float(ellipk(m)), float(ellipe(m))
    P = 1.0  # any load: the shape of the contact does not depend on it
    a = (3.0 * P * (K - E) / (2.0 * math.pi * E_star * A * m)) ** (1.0 / 3.0)
    delta = 3.0 * P * K / (2.0 * math.pi * a * E_star)
    return P / delta**1.5


def static_overlap(preload_N: float, beta_c: float) -> float:
    """delta0 = (F0 / beta_c)^(2/3) in m."""
    return (preload_N / beta_c) ** (2.0 / 3.0)


def linear_stiffness(preload_N: float, beta_c: float) -> float:
    """K = (3/2) beta_c^(2/3) F0^(1/3) in N/m, the contact stiffness about the preload."""
    return 1.5 * beta_c ** (2.0 / 3.0) * preload_N ** (1.0 / 3.0)
