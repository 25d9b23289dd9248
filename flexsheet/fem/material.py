"""Material of the virtual object (pure): small-strain E, ν, and for the hyperelastic reference the limiting
chain extensibility ``Jm`` of a Gent solid (∞, the default: neo-Hookean).

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
    """Isotropic material: Young's modulus ``E`` (Pa, > 0) and Poisson's ratio ``nu`` (0 ≤ ν < 0.5) — all the
    linear models read — and ``Jm`` (> 0, dimensionless; ``math.inf``: none), the Gent limiting value of I₁ −
    3 that only the hyperelastic reference reads (:mod:`flexsheet.fem.reference.hyperelastic`: W's
    isochoric-free part −μJm/2 ln(1 − (I₁ − 3)/Jm), Gent 1996; Jm → ∞ is neo-Hookean μ/2 (I₁ − 3)).

    Raises ``ValueError`` naming the field when out of range or not finite (``Jm`` may be ``inf``)."""

    E: float = 10e3
    nu: float = 0.45
    Jm: float = math.inf

    def __post_init__(self):
        if not (math.isfinite(self.E) and self.E > 0):
            raise ValueError(f"E must be a finite modulus > 0 Pa, got {self.E!r}")
        if not (math.isfinite(self.nu) and 0.0 <= self.nu < 0.5):
            raise ValueError(f"nu must be in [0, 0.5), got {self.nu!r}")
        if isinstance(self.Jm, bool) or not (self.Jm == math.inf or (math.isfinite(self.Jm) and self.Jm > 0)):
            raise ValueError(f"Jm must be > 0 (Gent limiting I1 - 3) or inf (neo-Hookean), got {self.Jm!r}")

    @classmethod
    def of_scene(cls, m) -> Material:
        """The material of a scene file's ``material`` (:class:`flexsheet.model.scene_parts.MaterialSpec`:
        ``model``, ``E``, ``nu``, ``Jm``): its ``Jm`` for ``model: gent``, else neo-Hookean (∞; the linear
        models read E, ν only). Raises ``ValueError`` as the constructor."""
        return cls(m.E, m.nu, m.Jm if m.model == "gent" else math.inf)

    @property
    def gent(self) -> bool:
        """True when the hyperelastic reference is a Gent solid (finite ``Jm``), False for neo-Hookean."""
        return math.isfinite(self.Jm)

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
        """Stable text key (cache keys; a neo-Hookean material keeps the key it had before ``Jm`` existed)."""
        return f"E={self.E:.9g},nu={self.nu:.9g}" + (f",Jm={self.Jm:.9g}" if self.gent else "")


SOFT_TISSUE = Material()
