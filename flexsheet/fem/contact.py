"""Displacement-driven fingertip contact on the cylinder (pure).

The fingertip is a rigid sphere of radius ``r`` whose leading point is the measured fingertip position ``tip``
(display frame, m). It pushes toward the cylinder axis: the push direction p̂ is the unit vector from ``tip``
to its projection on the axis, the undeformed contact point is where that line meets the side surface, and
the push depth is d = R − dist(tip, axis) (d ≤ 0: no contact). Every surface point inside the sphere gets the
imposed displacement that carries it, along p̂, onto the sphere's leading surface (bonded, i.e. no-slip,
Dirichlet contact, as in displacement-driven haptic FEM: Cotin et al. 1999, James & Pai 2001). The object's
reaction on the finger is minus the sum of the nodal forces on those points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ContactFinger", "finger_from_tip", "finger_at", "held_finger", "imposed_displacement"]


@dataclass(frozen=True)
class ContactFinger:
    """A fingertip sphere against the cylinder.

    ``center`` (3,) m sphere centre; ``direction`` (3,) unit push direction p̂ (into the object);
    ``radius`` m; ``depth`` m (≥ 0 when touching); ``contact_point`` (3,) m undeformed surface point under the
    finger; ``angle`` rad, azimuth of the contact point around +x (positive toward +z); ``axial`` m, the
    contact point's y offset from the cylinder centre. All in the display frame.
    """

    center: np.ndarray
    direction: np.ndarray
    radius: float
    depth: float
    contact_point: np.ndarray
    angle: float
    axial: float


def finger_at(angle: float, depth: float, radius: float, cyl_radius: float, cyl_center: np.ndarray,
              axial: float = 0.0) -> ContactFinger:
    """Finger pushing at azimuth ``angle`` (rad, around +x toward +z), axial offset ``axial`` (m) to ``depth``
    (m).

    Raises ``ValueError`` naming the argument when not finite, radius ≤ 0 or depth < 0."""
    for name, v in (("angle", angle), ("depth", depth), ("radius", radius), ("axial", axial)):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if radius <= 0:
        raise ValueError(f"radius must be > 0, got {radius!r}")
    if depth < 0:
        raise ValueError(f"depth must be >= 0, got {depth!r}")
    c0 = np.asarray(cyl_center, float)
    out = np.array([math.cos(angle), 0.0, math.sin(angle)])
    cp = c0 + np.array([0.0, axial, 0.0]) + cyl_radius * out
    tip = cp - depth * out
    return ContactFinger(tip + radius * out, -out, float(radius), float(depth), cp, float(angle),
                         float(axial))


def held_finger(p: np.ndarray, anchor: ContactFinger, radius: float, max_depth: float) -> ContactFinger:
    """The finger at tip ``p`` (3,) m while a push holds its contact: ``anchor``'s contact point, direction,
    azimuth and axial position, depth measured along the held direction (≥ 0). Raises ``ValueError`` naming
    the tip when it is deeper than ``max_depth`` m. Shared by the cylinder's and the scenes' contact."""
    depth = float((p - anchor.contact_point) @ anchor.direction)
    if depth > max_depth:
        raise ValueError(f"tip {p.tolist()} is {depth * 1e3:.1f} mm deep, beyond max_depth "
                         f"{max_depth * 1e3:.1f} mm")
    return ContactFinger(p - radius * anchor.direction, anchor.direction, float(radius), max(0.0, depth),
                  anchor.contact_point, anchor.angle, anchor.axial)


def finger_from_tip(tip: np.ndarray, radius: float, cyl_radius: float, cyl_length: float,
                    cyl_center: np.ndarray,
                    max_depth: float, anchor: ContactFinger | None = None,
                    sticky_depth: float = 0.005) -> ContactFinger:
    """Finger geometry from the measured fingertip position ``tip`` (3,) m, display frame.

    Without ``anchor`` the push direction points from ``tip`` to the cylinder axis. With ``anchor`` (the
    previous update's finger) whose depth is ≥ ``sticky_depth`` m, the contact point and push direction stay
    those of the anchor (a pressed finger does not slide; this also keeps pushes deeper than R defined) and
    the depth is (tip − contact_point)·p̂. Raises ``ValueError`` naming ``tip`` when it is not a finite (3,)
    vector, lies beyond an end face of the cylinder (|y − y_O| > L/2), on the back (support) half (x < x_O),
    on the axis, or deeper than ``max_depth`` (m). A tip outside the object gives depth 0 (no contact).
    """
    p = np.asarray(tip, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"tip must be a finite (3,) position in m, got {tip!r}")
    c0 = np.asarray(cyl_center, float)
    rel = p - c0
    axial = float(rel[1])
    if abs(axial) > cyl_length / 2:
        raise ValueError(f"tip {p.tolist()} is beyond the cylinder's end faces (|y - y_O| = {abs(axial):.4f} "
                         f"m > {cyl_length / 2:.4f} m)")
    if anchor is not None and anchor.depth >= sticky_depth:
        return held_finger(p, anchor, radius, max_depth)
    radial = np.array([rel[0], 0.0, rel[2]])
    rho = float(np.linalg.norm(radial))
    if rho < 1e-9:
        raise ValueError(f"tip {p.tolist()} is on the cylinder axis: push direction undefined")
    out = radial / rho
    if out[0] < 0:
        raise ValueError(f"tip {p.tolist()} is on the back (fixed support) half of the cylinder")
    depth = cyl_radius - rho
    if depth > max_depth:
        raise ValueError(f"tip {p.tolist()} is {depth * 1e3:.1f} mm deep, beyond max_depth "
                         f"{max_depth * 1e3:.1f} mm")
    cp = c0 + np.array([0.0, axial, 0.0]) + cyl_radius * out
    return ContactFinger(p + radius * out, -out, float(radius), max(0.0, depth), cp,
                  math.atan2(out[2], out[0]), axial)


def imposed_displacement(points: np.ndarray, finger: ContactFinger) -> tuple[np.ndarray, np.ndarray]:
    """Surface points inside the finger sphere and their imposed displacements.

    ``points`` (P, 3) m undeformed positions. Returns ``inside`` (P,) bool and ``u`` (P, 3) m, zero outside:
    a point at X = c + a·p̂ + t (t ⊥ p̂, |t| < r) with a < √(r² − |t|²) moves by (√(r² − |t|²) − a)·p̂.
    The derivative of ``u`` with respect to depth is p̂ on every inside point.
    """
    rel = np.asarray(points, float) - finger.center
    a = rel @ finger.direction
    t2 = np.einsum("ij,ij->i", rel, rel) - a * a
    r2 = finger.radius ** 2
    lead = np.sqrt(np.clip(r2 - t2, 0.0, None))
    inside = (t2 < r2) & (a < lead) & (finger.depth > 0)
    u = np.zeros_like(rel)
    u[inside] = (lead[inside] - a[inside])[:, None] * finger.direction[None, :]
    return inside, u
