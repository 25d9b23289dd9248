"""Sheet tension for compliance: clamp strain → membrane tension → normal stiffness at the contact, and back
(pure).

Model (the cheapest that captures the paper's Fig. 1 mechanism, "bias tension varies the compliance"):

* The urethane sheet (240 × 240 × 1 mm, paper §IV) is clamped along two opposite edges (the arms' clamps,
  ``axis_u``) and free along the other two. Pulling the clamps apart by the engineering strain ε (the
  ``stretch`` of every name here; λ = 1 + ε is the stretch ratio) puts it in uniaxial tension. Rubber is
  modelled as an incompressible neo-Hookean solid (Treloar, *The Physics of Rubber Elasticity*, 3rd ed., 1975,
  ch. 5; shear modulus μ = E/3): nominal stress P = μ (λ − λ⁻²), clamp force F = P·W₀·t₀, and tension per unit
  *current* width T = F / (W₀ λ^{-1/2}) = μ t₀ (λ − λ⁻²) λ^{1/2} [N/m].
* Young's modulus: E = 2.46 MPa, assuming Shore A 50 urethane rubber (the paper gives no grade), from
  Gent's hardness relation E[MPa] = 0.0981 (56 + 7.62336 S) / (0.137505 (254 − 2.54 S))
  (A. N. Gent, *Trans. Inst. Rubber Ind.* 34, 46 (1958)). Shore A 30…70 spans E ≈ 1.1…5.4 MPa.
* A fingertip pressing at distance a from one clamp and b from the other deflects a band of the sheet of
  effective width w (default 20 mm: a fingertip pad plus spreading; identify it with one push test).
  With no transverse tension (free edges) the band acts as a string under tension T·w, so the normal
  stiffness at the contact is k = T·w·(1/a + 1/b)  [N/m] (small-deflection linearisation; geometric
  stiffening at depths ≳ 5 % of a is neglected, and the sheet's bending stiffness
  D = E t³ / 12(1 − ν²) ≈ 2.7·10⁻⁴ N·m is negligible against T·a² at ε ≥ 1 %).
* Identified from pushes (:mod:`flexsheet.calibration.sheet`, ``flexsheet calibrate sheet``): a probe pressed
  to depth d at several points and stretches gives the force F = g·[T(ε + ε₀)·(w·d + w₂·d²) + b·d + a·d²] +
  c·d³, with g = 1/a + 1/b, the sheet's own strain offset ε₀ (pre-strain less grip slip), the band's growth
  with depth w₂ (the contact widens as the finger sinks in), the sheet's own stiffness b (N) and its growth a
  (N/m), which do not scale with the pull (a gripped sheet is stiffer at low tension than a string band:
  measured 0.063 against 0.038 of T·g·d at 3 mm, 24 and 235 N/m), and the membrane's stretching c (N/m³,
  large-deflection stiffening). The stiffness the finger feels at depth d is its slope, k = g·[T·(w + 2 w₂ d)
  + b + 2 a d] + 3 c d². The defaults (w₂ = b = a = c = ε₀ = 0) are the string band above.
* Where the finger presses: a membrane is not a string band, so the force also depends on the contact's place
  beyond g. Both are multiplied by h = 1 + p_u·(2u/L₀)² + p_v·(2v/L₀)² (u along the clamp line, v across, from
  the centre; L₀ the unstretched side), identified from presses at the centre, toward a clamp and toward a
  free edge (measured on the twin's presses: +5.6 % at u = 72 mm and −3.4 % at v = 36 mm without it). p_u =
  p_v = 0: the band alone.
* The inverse (requested stiffness → strain ε) is solved by safeguarded Newton on λ (k is monotone in λ).
  ε is clamped to [``min_stretch``, ``max_stretch``] and the clamp force to ``max_force``; when the
  object is stiffer than the sheet can present, the result says so (``saturated=True``).

Units: m, N, N/m, Pa; ``stretch`` is ε, the engineering strain between the clamps (dimensionless), never λ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flexsheet.model import geometry
from flexsheet.model.checks import check_positive
from flexsheet.model.sheet import clamp_half_span

__all__ = ["SheetMaterial", "TensionResult", "gent_modulus", "tension", "clamp_force", "contact_geometry",
           "stiffness",
           "press_force", "position_factor", "stretch_for_stiffness", "stretch_for_force",
           "max_stretch_within_force", "URETHANE_E"]


def gent_modulus(shore_a: float) -> float:
    """Young's modulus (Pa) of rubber of hardness ``shore_a`` (Shore A, 20…80), Gent (1958).

    Raises ``ValueError`` outside 0 < S < 100.
    """
    if not 0.0 < shore_a < 100.0:
        raise ValueError(f"shore_a must be in (0, 100), got {shore_a!r}")
    return 1e6 * 0.0981 * (56.0 + 7.62336 * shore_a) / (0.137505 * (254.0 - 2.54 * shore_a))


#: assumed Young's modulus of the paper's urethane rubber sheet, Pa (Shore A 50 through Gent's relation)
URETHANE_E = gent_modulus(50.0)


@dataclass(frozen=True)
class SheetMaterial:
    """The sheet and its limits. ``young`` Pa; ``thickness``, ``size`` (side, unstretched), ``contact_width``
    m; ``contact_growth`` w₂ (dimensionless), ``own_stiffness`` b (N), ``own_growth`` a (N/m), ``stretching``
    c (N/m³), ``strain_offset`` ε₀, ``position_u`` p_u and ``position_v`` p_v: the identified terms of the
    module doc (0: the string band); ``min_stretch``/``max_stretch`` engineering strain between the clamps;
    ``max_force`` N per clamp (arm pull limit).

    Defaults: paper §IV sheet; E per :data:`URETHANE_E`; max stretch 0.30 (well inside urethane's
    elongation at break, > 300 %, and in the range where neo-Hooke fits rubber within ~10 %, Treloar 1975);
    max force 40 N per clamp (an assumption for the RV-1A holding a static pull near its home pose — check
    against the arm bridge's joint-torque limits). Raises ``ValueError`` on a non-positive field.
    """

    young: float = URETHANE_E
    thickness: float = geometry.SHEET_THICKNESS
    size: float = geometry.SHEET_SIZE
    contact_width: float = 0.020
    contact_growth: float = 0.0
    own_stiffness: float = 0.0
    own_growth: float = 0.0
    stretching: float = 0.0
    strain_offset: float = 0.0
    position_u: float = 0.0
    position_v: float = 0.0
    min_stretch: float = 0.01
    max_stretch: float = 0.30
    max_force: float = 40.0

    def __post_init__(self) -> None:
        for name in ("young", "thickness", "size", "contact_width", "max_stretch", "max_force"):
            check_positive(name, getattr(self, name))
        if not (0.0 <= self.min_stretch < self.max_stretch):
            raise ValueError(f"min_stretch must be in [0, max_stretch), got {self.min_stretch!r}")
        for name in ("contact_growth", "own_stiffness", "own_growth", "stretching"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        if not (math.isfinite(self.strain_offset) and abs(self.strain_offset) < 0.1):
            raise ValueError(f"strain_offset must be finite and within ±0.1, got {self.strain_offset!r}")
        for name in ("position_u", "position_v"):
            v = getattr(self, name)
            if not (math.isfinite(v) and -0.9 <= v <= 5.0):      # h stays ≥ 0.1 over the whole sheet
                raise ValueError(f"{name} must be finite and within [-0.9, 5], got {v!r}")

    @property
    def mu(self) -> float:
        """Shear modulus μ = E/3 (incompressible), Pa."""
        return self.young / 3.0


def tension(stretch: float, mat: SheetMaterial) -> float:
    """Membrane tension T (N/m, per unit current width) at clamp strain ``stretch`` (uniaxial neo-Hooke at the
    sheet's strain ``stretch + mat.strain_offset``, 0 when that is not positive)."""
    lam = 1.0 + max(stretch + mat.strain_offset, 0.0)
    return mat.mu * mat.thickness * (lam - lam ** -2) * math.sqrt(lam)


def clamp_force(stretch: float, mat: SheetMaterial) -> float:
    """Total pull on each clamp, N: F = μ t₀ W₀ (λ − λ⁻²) at the sheet's strain (as :func:`tension`)."""
    lam = 1.0 + max(stretch + mat.strain_offset, 0.0)
    return mat.mu * mat.thickness * mat.size * (lam - lam ** -2)


def contact_geometry(stretch: float, mat: SheetMaterial, offset_u: float = 0.0) -> float:
    """g = 1/a + 1/b (1/m), a, b = L/2 ∓ ``offset_u`` the contact's distances to the clamps, L/2 =
    :func:`flexsheet.model.sheet.clamp_half_span`. Raises ``ValueError`` when the contact is not strictly
    between the clamps."""
    half = clamp_half_span(stretch, mat.size)
    a, b = half - offset_u, half + offset_u
    if a <= 0.0 or b <= 0.0:
        raise ValueError(f"offset_u must lie between the clamps (|offset_u| < {half:.4f} m), got "
                         f"{offset_u!r}")
    return 1.0 / a + 1.0 / b


def position_factor(mat: SheetMaterial, offset_u: float, offset_v: float = 0.0) -> float:
    """h = 1 + p_u·(2u/L₀)² + p_v·(2v/L₀)² (module doc) at the contact ``offset_u``, ``offset_v`` m from the
    sheet centre (along and across the clamp line)."""
    if mat.position_u == 0.0 and mat.position_v == 0.0:
        return 1.0
    h = 0.5 * mat.size
    return 1.0 + mat.position_u * (offset_u / h) ** 2 + mat.position_v * (offset_v / h) ** 2


def stiffness(stretch: float, mat: SheetMaterial, offset_u: float = 0.0, depth: float = 0.0,
              offset_v: float = 0.0) -> float:
    """Normal stiffness k (N/m) the finger feels at a contact ``offset_u`` m from the sheet centre along
    axis_u (current length) and ``offset_v`` m across, pushed ``depth`` m deep: k = h·(g·[T·(w + 2 w₂ d) + b +
    2 a d]
    + 3 c d²) (module doc; the string band T·w·(1/a + 1/b) with the default material). Raises ``ValueError``
    when the contact is not strictly between the clamps or the depth is negative."""
    if not (math.isfinite(depth) and depth >= 0.0):
        raise ValueError(f"depth must be finite and >= 0, got {depth!r}")
    g = contact_geometry(stretch, mat, offset_u)
    return position_factor(mat, offset_u, offset_v) * (
        g * (tension(stretch, mat) * (mat.contact_width + 2.0 * mat.contact_growth * depth)
             + mat.own_stiffness + 2.0 * mat.own_growth * depth)
        + 3.0 * mat.stretching * depth * depth)


def press_force(stretch: float, mat: SheetMaterial, offset_u: float, depth: float,
                offset_v: float = 0.0) -> float:
    """Force (N) of a press ``depth`` m deep at (``offset_u``, ``offset_v``): F = h·(g·[T·(w d + w₂ d²) + b d
    + a d²]
    + c d³) (module doc), the integral of :func:`stiffness` over the depth. Raises ``ValueError`` as
    :func:`stiffness`."""
    if not (math.isfinite(depth) and depth >= 0.0):
        raise ValueError(f"depth must be finite and >= 0, got {depth!r}")
    g = contact_geometry(stretch, mat, offset_u)
    d = depth
    return position_factor(mat, offset_u, offset_v) * (
        g * (tension(stretch, mat) * (mat.contact_width * d + mat.contact_growth * d * d)
             + mat.own_stiffness * d + mat.own_growth * d * d)
        + mat.stretching * d ** 3)


@dataclass(frozen=True, slots=True)
class TensionResult:
    """Inverse result: ``stretch`` (clamped), ``tension`` N/m, ``stiffness`` N/m presented, ``force`` N per
    clamp, ``saturated``: the requested stiffness was above (``"object_stiffer_than_sheet"``) or below
    (``"object_softer_than_sheet"``) what the limits allow, else ``""``."""

    stretch: float
    tension: float
    stiffness: float
    force: float
    saturated: str = ""


def max_stretch_within_force(mat: SheetMaterial) -> float:
    """Largest stretch allowed by both max_stretch and max_force (force is monotone in λ)."""
    if clamp_force(mat.max_stretch, mat) <= mat.max_force:
        return mat.max_stretch
    lo, hi = 0.0, mat.max_stretch
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if clamp_force(mid, mat) <= mat.max_force:
            lo = mid
        else:
            hi = mid
    return lo


def stretch_for_stiffness(k_target: float, mat: SheetMaterial, offset_u: float = 0.0,
                          eps_max: float | None = None, depth: float = 0.0,
                          offset_v: float = 0.0) -> TensionResult:
    """Stretch that makes the normal stiffness at the contact, pushed ``depth`` m deep, equal ``k_target`` N/m
    (inverse of :func:`stiffness`).

    Safeguarded Newton on ε ∈ [min_stretch, ε_max] (k is strictly increasing in ε for |offset_u| < L/2),
    where ε_max is the largest stretch within ``max_stretch`` and ``max_force`` (pass ``eps_max`` to reuse a
    precomputed value). Returns a :class:`TensionResult`; ``saturated`` reports clamping. Raises
    ``ValueError`` if ``k_target`` is negative or not finite.
    """
    if not (math.isfinite(k_target) and k_target >= 0.0):
        raise ValueError(f"k_target must be finite and >= 0, got {k_target!r}")
    e, sat = _invert(k_target, lambda e: stiffness(e, mat, offset_u, depth, offset_v), mat, eps_max)
    return TensionResult(e, tension(e, mat), stiffness(e, mat, offset_u, depth, offset_v),
                         clamp_force(e, mat), sat)


def stretch_for_force(force: float, mat: SheetMaterial, offset_u: float, depth: float,
                      eps_max: float | None = None, offset_v: float = 0.0) -> TensionResult:
    """Stretch at which a press ``depth`` m deep at (``offset_u``, ``offset_v``) meets the force ``force`` N
    (inverse of :func:`press_force`, increasing in ε): the sheet's force–depth follows the object's along a
    press when this is solved at each depth. Limits and ``saturated`` as :func:`stretch_for_stiffness`; the
    result's ``stiffness`` is the incremental one there. Raises ``ValueError`` for a negative or non-finite
    force, or a depth that is not > 0."""
    if not (math.isfinite(force) and force >= 0.0):
        raise ValueError(f"force must be finite and >= 0, got {force!r}")
    if not (math.isfinite(depth) and depth > 0.0):
        raise ValueError(f"depth must be finite and > 0, got {depth!r}")
    e, sat = _invert(force, lambda e: press_force(e, mat, offset_u, depth, offset_v), mat, eps_max)
    return TensionResult(e, tension(e, mat), stiffness(e, mat, offset_u, depth, offset_v),
                         clamp_force(e, mat), sat)


def _invert(target: float, f_of, mat: SheetMaterial, eps_max: float | None) -> tuple[float, str]:
    """(ε, saturated) with ``f_of(ε)`` = ``target`` for an increasing ``f_of`` on [min_stretch, ε_max]: the
    bound and ``object_softer_than_sheet`` / ``object_stiffer_than_sheet`` outside; safeguarded Newton
    inside."""
    emax = max_stretch_within_force(mat) if eps_max is None else eps_max
    lo, hi = mat.min_stretch, emax
    flo, fhi = f_of(lo), f_of(hi)
    if target <= flo:
        return lo, ("object_softer_than_sheet" if target < flo * (1 - 1e-9) else "")
    if target >= fhi:
        return hi, ("object_stiffer_than_sheet" if target > fhi * (1 + 1e-9) else "")
    e = lo + (hi - lo) * (target - flo) / (fhi - flo)            # linear guess, then Newton in a bracket
    for _ in range(30):
        r = f_of(e) - target
        if abs(r) <= 1e-10 * max(1.0, target):
            break
        if r > 0:
            hi = e
        else:
            lo = e
        h = 1e-7
        g = (f_of(e + h) - f_of(e - h)) / (2 * h) if e - h > -1.0 else 0.0
        en = e - r / g if g > 0 else 0.5 * (lo + hi)
        e = en if lo < en < hi else 0.5 * (lo + hi)
    return e, ""
