"""The geometrically nonlinear reference's mesh (pure): its spec (:class:`RefSpec`, sizes and refinement, a
stable cache key) and the half or quarter cylinder mesh it gives for a push at an azimuth
(:func:`reference_mesh`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flexsheet.fem.mesh import TetMesh, cylinder_part_mesh

__all__ = ["RefSpec", "reference_mesh"]


@dataclass(frozen=True)
class RefSpec:
    """Mesh of the reference: ``h`` global size (m), ``h_fine`` size (m) within ``refine_radius`` (m) of the
    contact point, or (``path_depth`` > 0, m) of the whole push path from the contact point down to that depth
    (:func:`flexsheet.fem.mesh.cylinder_part_mesh`); ``half_z`` also use the z mirror plane (azimuth-0 pushes
    only); ``skin_h`` > 0 (m): that size in the surface layer ``skin_depth`` thick within ``skin_radius`` of
    the contact point (the material that wraps the fingertip and lines the crater); ``tip_h`` > 0 (m): that
    size within ``tip_radius`` (m) of the contact point itself, graded to ``h`` over a further ``tip_radius``
    (the material that ends up over the fingertip, stretched several times over: docs/fem.md, fold study);
    ``cut``: the mesh is conforming to the plane through the cylinder's axis and the push axis (nodes on it,
    as a quarter model has on its mirror plane), for half models (a quarter model has it: ignored); ``rim``:
    the support's rim (x = x_O) on mesh lines of size ``h_fine``. Raises ``ValueError``."""

    h: float = 0.010
    h_fine: float = 0.002
    refine_radius: float = 0.018
    half_z: bool = False
    path_depth: float = 0.0
    skin_h: float = 0.0
    skin_radius: float = 0.020
    skin_depth: float = 0.005
    cut: bool = False
    tip_h: float = 0.0
    tip_radius: float = 0.005
    rim: bool = False

    def __post_init__(self):
        for name in ("h", "h_fine"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0005 <= v <= 0.05):
                raise ValueError(f"{name} must be in [0.0005, 0.05] m, got {v!r}")
        if self.h_fine > self.h:
            raise ValueError(f"h_fine must be <= h, got {self.h_fine!r} > {self.h!r}")
        if not (self.skin_h == 0.0 or (math.isfinite(self.skin_h) and 0.0005 <= self.skin_h <= self.h_fine)):
            raise ValueError(f"skin_h must be 0 (no skin) or in [0.0005, h_fine={self.h_fine:g}] m, got "
                             f"{self.skin_h!r}")
        for name in ("skin_radius", "skin_depth"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0 m, got {v!r}")
        if not (self.tip_h == 0.0 or (math.isfinite(self.tip_h) and 0.0005 <= self.tip_h <= self.h_fine)):
            raise ValueError(f"tip_h must be 0 (no tip refinement) or in [0.0005, h_fine={self.h_fine:g}] m, "
                             f"got {self.tip_h!r}")
        if not (math.isfinite(self.tip_radius) and self.tip_radius >= max(self.tip_h, 1e-4)):
            raise ValueError(f"tip_radius must be >= tip_h (one element), got {self.tip_radius!r}")
        if self.skin_h > 0 and self.skin_depth < self.skin_h:
            raise ValueError(f"skin_depth must be >= skin_h = {self.skin_h:g} m (one element thick), got "
                             f"{self.skin_depth!r}")

    def key(self) -> str:
        """Stable text key (cache keys)."""
        k = f"h={self.h:.6g},hf={self.h_fine:.6g},rr={self.refine_radius:.6g},hz={int(self.half_z)}"
        k += f",pd={self.path_depth:.6g}" if self.path_depth > 0 else ""
        k += f",sk={self.skin_h:.6g}/{self.skin_radius:.6g}/{self.skin_depth:.6g}" if self.skin_h > 0 else ""
        k += f",tip={self.tip_h:.6g}/{self.tip_radius:.6g}" if self.tip_h > 0 else ""
        k += ",rim" if self.rim else ""
        return k + (",cut" if self.cut and not self.half_z else "")  # a quarter model has the plane anyway


def reference_mesh(spec: RefSpec, angle_deg: float) -> TetMesh:
    """Half (or quarter, ``spec.half_z``) cylinder mesh refined around the push point at ``angle_deg``."""
    if spec.half_z and abs(angle_deg) > 1e-9:
        raise ValueError(f"half_z needs a push at azimuth 0, got {angle_deg!r} deg")
    return cylinder_part_mesh(spec.h, spec.h_fine, spec.refine_radius, (float(angle_deg),), half_y=True,
                              half_z=spec.half_z, path_depth=spec.path_depth,
                              skin=(spec.skin_h, spec.skin_radius, spec.skin_depth) if spec.skin_h > 0
                              else None,
                              tip=(spec.tip_h, spec.tip_radius) if spec.tip_h > 0 else None,
                              cut_deg=float(angle_deg) if spec.cut and not spec.half_z else None,
                              rim=spec.rim)
