"""The viewer's keep-out volume: clearance of the sheet, clamps and arms from the tracked head (pure).

Model: the head is a sphere of radius ``head_radius`` about a centre ``C = V + eye_to_head`` (``V`` the
tracked cyclopean eye, display frame; the viewer faces −x, so the head's centre lies behind the eyes, at
larger x), grown by ``margin``. The keep-out volume is the sphere of radius ``R = head_radius + margin`` about
``C``. A part's *clearance* is its smallest distance to that sphere's boundary: ``min |p − C| − R`` over its
points, or over its segments for the arm links (capsules: minus the link radius); negative inside.

* The sheet is sampled as a grid over its whole flat rectangle (every ≤ ``spacing`` m) — a head leaning in
  meets the middle of the sheet before its outline — and each clamp bar as two lines, on the sheet and
  ``CLAMP_DEPTH`` behind it (:func:`sheet_points`). A pushed sheet deflects away from the viewer, so the
  flat sheet is the conservative one. Sampling overestimates the clearance of a flat part by at most
  e = ``spacing/√2`` (head centre on the part), and by ≈ e²/(2d) with d the distance from the head centre:
  ≤ 0.7 mm for d ≥ 0.15 m (the keep-out boundary) at the default 0.02 m spacing.
* An arm is the chain of segments between consecutive points of
  :meth:`flexsheet.arm.kinematics.ArmKinematics.joint_origins` (base, J1…J6, clamp): link k (0…6) is the
  segment carried by joint k (link 0 the base column, link 6 J6 to the flange face). A link's clearance is the
  closed-form point–segment distance minus ``link_radius`` (0.05 m default). Link 6 stops ``CLAMP_REACH``
  short of the clamp point: the clamp itself is thin and lies on the sheet's edge, where the clamp points of
  :func:`sheet_points` stand for it (a 0.05 m capsule ending at the jaw line would bulge 0.05 m in front of
  the sheet). The J3→J4 chord passes 0.039 m from the URDF's elbow corner, inside the default link radius.
* Speed: within ``near_distance`` of the keep-out boundary (and inside it) the sheet and arms move at no more
  than ``reduced_speed``, ISO 10218-1:2011 §5.6 (reduced speed control: ≤ 250 mm/s at the tool); beyond it
  the limit is ``inf`` (the planner's own limits apply). Inside the volume the caller does not advance: it
  backs off (:func:`retreat_point`) at that speed.

:func:`check_targets` is the one call the planner and the arm bridges make. Units m, s; display frame. This
module does not import :mod:`flexsheet.arm` at run time (the arm package may import it); ``kin`` is any object
with ``joint_origins(q) -> (8, 3)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.checks import check_point, check_positive, check_unit
from flexsheet.model.sheet import sheet_rotation

if TYPE_CHECKING:
    from flexsheet.arm.kinematics import ArmKinematics

__all__ = ["CLAMP_DEPTH", "CLAMP_REACH", "CLAMP_BAR_HALF", "KeepOut", "KeepOutVerdict", "sheet_points",
           "arm_segments", "arm_clearance", "arm_keepout_clearance", "check_targets", "retreat_point"]

#: depth of a clamp bar behind the sheet, m (ASSUMED: the clamp is not specified beyond the URDF's jaw line)
CLAMP_DEPTH = 0.02
#: flange face to clamp jaw line, m: the clamp's length in flexsheet/arm/rv1a.urdf (``clamp_mount``: 0.0193 m
#: J6 origin to flange face + 0.030 m assumed clamp)
CLAMP_REACH = 0.030
#: m: half the clamp bar's length along the clamp frame's z axis (the sheet's v), about the clamp point
CLAMP_BAR_HALF = 0.5 * geometry.SHEET_SIZE


def _points(name: str, p) -> np.ndarray:
    """``p`` as a finite (N, 3) float64 array with N ≥ 1; raises ``ValueError`` naming ``name``."""
    try:
        a = np.asarray(p, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite (N, 3) array in m, got {p!r}") from None
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1 or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite (N, 3) array in m with N >= 1, got shape {a.shape}")
    return a


def _segment_distances(c: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K,) m: distance from the point ``c`` (3,) to each segment a[k]–b[k] ((K, 3) each), closed form:
    t = clip((c − a)·(b − a) / |b − a|², 0, 1), d = |a + t(b − a) − c| (t = 0 for a zero-length segment)."""
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    num = np.einsum("ij,ij->i", c - a, ab)
    t = np.clip(np.divide(num, den, out=np.zeros_like(den), where=den > 0.0), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - c, axis=1)


@dataclass(frozen=True)
class KeepOut:
    """The viewer's keep-out sphere from the tracked eye (see the module doc).

    ``head_radius`` m (> 0, head sphere about the head's centre), ``margin`` m (≥ 0, added to it),
    ``eye_to_head`` (3,) m (offset from the cyclopean eye V to the head centre, display frame; default 0.08 m
    behind the eyes and 0.02 m up), ``near_distance`` m (> 0: closer to the boundary than this, the reduced
    speed applies), ``reduced_speed`` m/s (> 0; ISO 10218-1:2011 §5.6, 250 mm/s). Raises ``ValueError`` naming
    the field for a non-finite, non-positive (negative margin) or malformed value.
    """

    head_radius: float = 0.10
    margin: float = 0.05
    eye_to_head: tuple[float, float, float] = (0.08, 0.0, 0.02)
    near_distance: float = 0.15
    reduced_speed: float = 0.25

    def __post_init__(self) -> None:
        for name in ("head_radius", "near_distance", "reduced_speed"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        object.__setattr__(self, "margin", check_positive("margin", self.margin, allow_zero=True))
        off = check_point("eye_to_head", self.eye_to_head)
        object.__setattr__(self, "eye_to_head", tuple(float(x) for x in off))

    @property
    def radius(self) -> float:
        """Keep-out sphere radius head_radius + margin, m."""
        return self.head_radius + self.margin

    def center(self, V) -> np.ndarray:
        """Head centre (3,) m = ``V`` + ``eye_to_head`` for the cyclopean eye ``V`` (3,) m, display frame.
        Raises ``ValueError`` naming ``V`` if it is not a finite (3,) point."""
        return check_point("V", V) + np.asarray(self.eye_to_head)

    def clearance(self, V, points) -> float:
        """Smallest distance (m) from ``points`` (N, 3) m to the keep-out boundary for the eye ``V`` (3,) m:
        min |p − C| − radius; negative inside. Raises ``ValueError`` naming ``V`` or ``points``."""
        c = self.center(V)
        return float(np.min(np.linalg.norm(_points("points", points) - c, axis=1))) - self.radius

    def clearance_segments(self, V, a, b) -> float:
        """Smallest distance (m) from the segments a[k]–b[k] (``a``, ``b`` (K, 3) m) to the keep-out boundary
        for the eye ``V`` (3,) m (zero-radius capsules; subtract a link radius for thick links); negative
        inside. Raises ``ValueError`` naming ``V``, ``a`` or ``b`` (also when their shapes differ)."""
        c = self.center(V)
        a, b = _points("a", a), _points("b", b)
        if a.shape != b.shape:
            raise ValueError(f"a and b must have the same (K, 3) shape, got {a.shape} and {b.shape}")
        return float(np.min(_segment_distances(c, a, b))) - self.radius

    def speed_limit(self, clearance: float) -> float:
        """Speed limit (m/s) at ``clearance`` (m): ``reduced_speed`` when clearance < ``near_distance``
        (inside included), else ``inf``. Raises ``ValueError`` naming ``clearance`` if it is NaN or not a
        number."""
        try:
            x = float(clearance)
        except (TypeError, ValueError):
            raise ValueError(f"clearance must be a number in m, got {clearance!r}") from None
        if math.isnan(x):
            raise ValueError(f"clearance must not be NaN, got {clearance!r}")
        return self.reduced_speed if x < self.near_distance else math.inf


@dataclass(frozen=True)
class KeepOutVerdict:
    """Result of :func:`check_targets`: ``clearance`` m (of the nearest part; negative inside), ``inside``
    (clearance < 0), ``what`` (the nearest part: "sheet", "left clamp", "right arm link 5", …) and
    ``speed_limit`` m/s (:meth:`KeepOut.speed_limit` of the clearance)."""

    clearance: float
    inside: bool
    what: str
    speed_limit: float


def sheet_points(origin, normal, axis_u, half_span: float, size: float = geometry.SHEET_SIZE,
                 spacing: float = 0.02) -> dict[str, np.ndarray]:
    """Sample points (display frame, m) of the flat sheet and its clamp bars for the keep-out test.

    The sheet centred at ``origin`` (3,) m with unit ``normal`` (toward the viewer) and ``axis_u`` (right →
    left clamp), clamps at u = ±``half_span`` m, free edges at v = ±``size``/2 (``size`` the unstretched side,
    m). Returns ``{"sheet": (Ns, 3), "left clamp": (Nc, 3), "right clamp": (Nc,
    3)}``: the sheet as a grid over
    |u| ≤ half_span, |v| ≤ size/2 (corners and outline included) and each clamp bar as two lines along v at
    u = ±half_span, on the sheet and ``CLAMP_DEPTH`` behind it (−normal), all every ≤ ``spacing`` m. Home
    sheet, defaults: 13 × 13 sheet points, 26 per clamp. Raises ``ValueError`` naming the argument for a bad
    vector (:func:`flexsheet.model.sheet.sheet_rotation`) or a non-positive length.
    """
    R = sheet_rotation(normal, axis_u)
    o = check_point("origin", origin)
    a = check_positive("half_span", half_span)
    b = 0.5 * check_positive("size", size)
    h = check_positive("spacing", spacing)
    n, eu, ev = R[:, 0], R[:, 1], R[:, 2]
    u = np.linspace(-a, a, math.ceil(2.0 * a / h - 1e-9) + 1)
    v = np.linspace(-b, b, math.ceil(2.0 * b / h - 1e-9) + 1)
    grid = o + u[:, None, None] * eu + v[None, :, None] * ev
    out = {"sheet": grid.reshape(-1, 3)}
    depth = np.linspace(0.0, CLAMP_DEPTH, math.ceil(CLAMP_DEPTH / h - 1e-9) + 1)
    for name, s in (("left clamp", 1.0), ("right clamp", -1.0)):
        bar = o + s * a * eu + v[:, None, None] * ev - depth[None, :, None] * n
        out[name] = bar.reshape(-1, 3)
    return out


def arm_segments(kin: ArmKinematics, q) -> tuple[np.ndarray, np.ndarray]:
    """The arm's links as segments (a (7, 3), b (7, 3)) m, display frame, at joints ``q`` (6,) rad: a[k]–b[k]
    is link k (0 base column … 5 wrist, 6 J6 to the flange face), between consecutive rows of
    ``kin.joint_origins(q)`` (:meth:`flexsheet.arm.kinematics.ArmKinematics.joint_origins`: base, J1…J6,
    clamp), the last one shortened by ``CLAMP_REACH`` (see the module doc). Raises ``ValueError`` naming
    ``q``.
    """
    p = kin.joint_origins(q)
    a, b = p[:-1], p[1:].copy()
    d = b[-1] - a[-1]
    n = float(np.linalg.norm(d))
    if n > CLAMP_REACH:
        b[-1] -= d * (CLAMP_REACH / n)
    return a, b


def arm_clearance(keepout: KeepOut, V, kin: ArmKinematics, q, link_radius: float = 0.05) -> float:
    """Clearance (m) of one arm at joints ``q`` (6,) rad from the keep-out sphere for the eye ``V`` (3,) m:
    :meth:`KeepOut.clearance_segments` of :func:`arm_segments` minus ``link_radius`` m (≥ 0; links as
    capsules). Raises ``ValueError`` naming ``V``, ``q`` or ``link_radius``."""
    r = check_positive("link_radius", link_radius, allow_zero=True)
    return keepout.clearance_segments(V, *arm_segments(kin, q)) - r


def arm_keepout_clearance(keepout: KeepOut, V, kin: ArmKinematics, q,
                          link_radius: float = 0.05) -> tuple[float, str]:
    """(clearance m, what: "link k" or "clamp bar") of one arm at joints ``q`` (6,) rad from the keep-out of
    the eye ``V`` (3,) m: the smaller of :func:`arm_clearance` (links as ``link_radius`` capsules) and of its
    clamp bar, the segment ±:data:`CLAMP_BAR_HALF` along the clamp frame's z axis about the clamp point. The
    one test of an arm: each bridge refuses a target below 0 at its own margin (``hold:keep_out``), the
    planner's head guard keeps it above 0 at its larger one. Raises ``ValueError`` naming ``V`` or ``q``."""
    r = check_positive("link_radius", link_radius, allow_zero=True)
    c = keepout.center(V)
    a, b = arm_segments(kin, q)
    d = _segment_distances(c, a, b) - r
    k = int(np.argmin(d))
    T = kin.fk(q)
    p, z = T[:3, 3], T[:3, 2]
    bar = float(_segment_distances(c, (p - CLAMP_BAR_HALF * z)[None], (p + CLAMP_BAR_HALF * z)[None])[0])
    if bar < d[k]:
        return bar - keepout.radius, "clamp bar"
    return float(d[k]) - keepout.radius, f"link {k}"


def check_targets(keepout: KeepOut, V, sheet_pts, arm_segs: Mapping | None = None, *,
                  link_radius: float = 0.05) -> KeepOutVerdict:
    """Keep-out verdict for a sheet and its arms (the planner's targets or the bridges' commands).

    ``V`` (3,) m: the tracked eye. ``sheet_pts``: a mapping part name → (N, 3) m points
    (:func:`sheet_points`), or one (N, 3) array (named "sheet"). ``arm_segs``: optional mapping arm name → (a,
    b), (K, 3) m each (:func:`arm_segments`), e.g. ``{"left arm": ..., "right arm": ...}``; segment k is
    reported as "<arm name> link k" and its clearance is reduced by ``link_radius`` m (≥ 0). Returns the
    nearest part's :class:`KeepOutVerdict` (ties go to the first part given). Raises ``ValueError`` naming the
    bad argument.
    """
    c = keepout.center(V)
    r = check_positive("link_radius", link_radius, allow_zero=True)
    parts = {"sheet": sheet_pts} if not isinstance(sheet_pts, Mapping) else sheet_pts
    best, what = math.inf, ""
    for name, pts in parts.items():
        d = float(np.min(np.linalg.norm(_points(f"sheet_pts[{name!r}]", pts) - c, axis=1)))
        if d < best:
            best, what = d, str(name)
    for name, seg in (arm_segs or {}).items():
        try:
            a, b = seg
        except (TypeError, ValueError):
            raise ValueError(f"arm_segs[{name!r}] must be a pair (a, b) of (K, 3) arrays, got "
                             f"{seg!r}") from None
        a, b = _points(f"arm_segs[{name!r}] a", a), _points(f"arm_segs[{name!r}] b", b)
        if a.shape != b.shape:
            raise ValueError(f"arm_segs[{name!r}] a and b must have the same shape, got {a.shape}, {b.shape}")
        d = _segment_distances(c, a, b) - r
        k = int(np.argmin(d))
        if d[k] < best:
            best, what = float(d[k]), f"{name} link {k}"
    clearance = best - keepout.radius
    return KeepOutVerdict(clearance, clearance < 0.0, what, keepout.speed_limit(clearance))


def retreat_point(keepout: KeepOut, V, origin, normal, step: float) -> np.ndarray:
    """Where to move the sheet centre (3,) m to back off from the head of the eye ``V`` (3,) m.

    The away-from-head direction ``origin − C`` projected onto −x: the sheet moves along −x (toward its home
    side, away from the viewer, who sits at +x) by t = clip(need, 0, ``step``) m, where ``need`` is the move
    that puts the sheet's plane (through ``origin`` with unit ``normal`` (3,), taken with n_x ≥ 0)
    ``radius + near_distance`` in front of the head centre C: need = (radius + near_distance − n·(C − origin))
    / n_x (the full ``step`` when n_x < 1e-3, where moving along x does not move the plane). The infinite
    plane is nearer than the sheet, so ``need`` errs on the far side. If the head centre is not in front of
    the sheet centre (C_x ≤ origin_x), −x is not away from it and ``origin`` is returned unchanged: the caller
    holds. Raises ``ValueError`` naming ``V``, ``origin``, ``normal`` or ``step`` (> 0).
    """
    c = keepout.center(V)
    o = check_point("origin", origin)
    n = check_unit("normal", normal, tol=1e-6)
    s = check_positive("step", step)
    if c[0] <= o[0]:
        return o.copy()
    if n[0] < 0.0:
        n = -n
    nx = float(n[0])
    target = keepout.radius + keepout.near_distance
    need = s if nx < 1e-3 else (target - float(n @ (c - o))) / nx
    t = min(max(need, 0.0), s)
    return o - np.array([t, 0.0, 0.0])
