"""Linear-elastic material of the virtual object (pure).

Defaults: E = 10 kPa, ν = 0.45, a soft-tissue value. Sources: soft-tissue phantoms span agar 5–81 kPa,
gelatine 17–85 kPa, silicone (Ecoflex 00-30) 5–112 kPa; breast fat and glandular tissue measure 3–20 kPa
(Samani, Zubovits & Plewes, Phys. Med. Biol. 52, 2007; Wells & Liang, J. R. Soc. Interface 8, 2011 —
figures recalled, see docs/fem.md). ν = 0.45 rather than 0.49 because P1 tetrahedra lock as ν → 0.5; the
experiment's P2 reference shows the effect. With displacement-driven contact the displacement field does not
depend on E at all (only on ν); forces and stiffness scale linearly with E.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Material", "SOFT_TISSUE"]


@dataclass(frozen=True)
class Material:
    """Isotropic linear elasticity: Young's modulus ``E`` (Pa, > 0) and Poisson's ratio ``nu`` (0 ≤ ν < 0.5).

    Raises ``ValueError`` naming the field when out of range or not finite."""

    E: float = 10e3
    nu: float = 0.45

    def __post_init__(self):
        if not (math.isfinite(self.E) and self.E > 0):
            raise ValueError(f"E must be a finite modulus > 0 Pa, got {self.E!r}")
        if not (math.isfinite(self.nu) and 0.0 <= self.nu < 0.5):
            raise ValueError(f"nu must be in [0, 0.5), got {self.nu!r}")

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters (λ, μ) in Pa (λ = Eν/((1+ν)(1−2ν)), μ = E/(2(1+ν)))."""
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        mu = self.E / (2 * (1 + self.nu))
        return lam, mu

    @property
    def E_star(self) -> float:
        """Plane-strain modulus E* = E/(1−ν²), Pa (Hertz contact against a rigid sphere)."""
        return self.E / (1 - self.nu ** 2)

    def key(self) -> str:
        """Stable text key (cache keys)."""
        return f"E={self.E:.9g},nu={self.nu:.9g}"


SOFT_TISSUE = Material()
