"""Elastic materials of the cylinders (SI units)."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["FUSED_QUARTZ", "Material"]


@dataclass(frozen=True)
class Material:
    """An isotropic elastic material.

    Attributes
    ----------
    name: label.
    youngs_modulus_Pa: E in Pa.
    density_kg_per_m3: rho in kg/m^3.
    poisson_ratio: nu (dimensionless, -1 < nu < 0.5).
    """

    name: str
    youngs_modulus_Pa: float
    density_kg_per_m3: float
    poisson_ratio: float

    @property
    def shear_modulus_Pa(self) -> float:
        """G = E / (2 (1 + nu)) in Pa."""
        return self.youngs_modulus_Pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def shear_coefficient(self) -> float:
        """Timoshenko shear coefficient of a solid circular section,
        kappa = 6 (1 + nu)^2 / (7 + 12 nu + 4 nu^2)."""
        nu = self.poisson_ratio
        return 6.0 * (1.0 + nu) ** 2 / (7.0 + 12.0 * nu + 4.0 * nu**2)

    @property
    def contact_modulus_Pa(self) -> float:
        """E* = E / (2 (1 - nu^2)) for two bodies of this material, in Pa."""
        return self.youngs_modulus_Pa / (2.0 * (1.0 - self.poisson_ratio**2))

    @property
    def bar_speed_m_per_s(self) -> float:
        """sqrt(E / rho) in m/s."""
        return math.sqrt(self.youngs_modulus_Pa / self.density_kg_per_m3)


#: fused quartz, standard values (physics.md)
FUSED_QUARTZ = Material("fused quartz", 72.0e9, 2200.0, 0.17)
