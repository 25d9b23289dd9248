"""The sheet's geometry, in one place: clamp poses ↔ sheet frame, stretch, and the pushed membrane (pure).

**Sheet frame and clamps** (convention of :mod:`flexsheet.model.geometry`): the sheet centre ``origin``, the
unit ``normal`` (toward the user), ``axis_u`` (right → left clamp) and ``axis_v = normal × axis_u``. The two
clamp frames ``T_display_clamp`` sit at the middle of the clamped edges, ``origin ± a·axis_u`` with the half
span ``a = size·(1 + stretch)/2`` (``size`` the unstretched side between the clamps, ``stretch`` the
engineering strain), and carry the sheet's orientation (columns of R = normal, axis_u, axis_v).
:func:`clamp_half_span`, :func:`clamp_points` and :func:`clamp_poses` go from the sheet to the clamps (the
planner, the arm bridge's home pose, the experiments); :func:`frame_from_clamps` and
:meth:`SheetSurface.from_clamps` go back from measured clamps to the sheet (the world twin, the renderer),
and :func:`stretch_of_span` recovers the stretch. Every other module calls these; none recomputes them.

**Shape of the pushed sheet**: a pre-tensioned membrane clamped on two edges, free on two, pushed by a
finger. Model (stated here because the paper does not give one; §III-C only says "exact correction
requires accurate measurement of the shape of the sheet"):

* Small-slope membrane under uniform in-plane tension: ``T_u w_uu + T_v w_vv = -p(u, v)`` for the
  out-of-plane deflection ``w`` (m, positive along ``-normal``, i.e. away from the user). Bending of the 1 mm
  rubber is neglected (membrane limit; Timoshenko & Woinowsky-Krieger, *Theory of Plates and Shells*, §1 and
  the membrane equation of Love), as is the extra tension the push itself adds (it is folded into ``T_u``,
  ``T_v``; only their ratio ``beta = T_v / T_u`` matters for the shape).
* Boundary conditions in the sheet frame (``u`` along ``axis_u``, ``v`` along ``axis_v``): Dirichlet
  ``w = 0`` on the clamped edges ``u = ±a`` (the arms' clamps), and zero transverse force ``∂w/∂v = 0`` on
  the free edges ``v = ±b``.
* Load: the fingertip presses a short segment ``|u - u0| ≤ r``, ``v = v0`` (``r`` = contact radius) with
  unknown force; the force is fixed by the measured depth: ``w(u0, v0) = S``. A point load would give the
  logarithmic singularity of the 2-D Green's function; the finite contact keeps the depth finite.
* Solution: sine series in ``u`` (modes ``φ_k(u) = sin(λ_k (u + a))``, ``λ_k = kπ / 2a``) times the 1-D
  Neumann Green's function in ``v`` of ``g'' − μ_k² g = −δ`` (``μ_k = λ_k / √beta``):
  ``G_k(v, v0) = cosh(μ(b + v<)) cosh(μ(b − v>)) / (μ sinh 2μb)``, evaluated in an overflow-free
  exponential form (also used by the GLSL fine model). ``w = c Σ_k q_k φ_k(u) G_k(v, v0)`` with
  ``q_k = φ_k(u0) sinc(λ_k r)`` (the exact modal projection of the segment load) and ``c`` chosen so that
  ``w(u0, v0) = S``.

``modes`` sets the truncation: the series converges like ``Σ 1/k²`` beyond ``k ≈ 2a / r``; the renderer's
fine correction uses a cheap fit of this shape with fewer modes (see docs/renderer.md for the error this
costs). It is an *estimator's* model: the twin's true pushed sheet is the nonlinear FEM of
:mod:`flexsheet.model.sheet_fem` (what the world publishes since the honest-twin issue).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.checks import check_point, check_pose, check_positive, check_unit

__all__ = ["Membrane", "DeflectionGrid", "SheetSurface", "TRUE_MODES", "neumann_green", "series_deflection",
           "sheet_rotation", "clamp_half_span", "stretch_of_span",
           "clamp_points", "clamp_poses", "frame_from_clamps"]

#: number of modes of the reference ("true") membrane shape
TRUE_MODES = 256
#: tolerance on a measured clamp pose's rotation block (|RᵀR − I|, last row): the renderer's acceptance
_POSE_TOL = 1e-3


# -- sheet frame <-> clamps ----------------------------------------------------------------------------
def sheet_rotation(normal, axis_u) -> np.ndarray:
    """Rotation (3, 3) whose columns are (normal, axis_u, axis_v), axis_v = normal × axis_u.

    ``normal`` and ``axis_u`` are (3,) unit vectors in the display frame (|v| = 1 within 1e-6), orthogonal
    within 1e-6. Raises ``ValueError`` naming the argument if either is not finite, not unit length, or the
    two are not orthogonal.
    """
    n = check_unit("normal", normal, tol=1e-6)
    u = check_unit("axis_u", axis_u, tol=1e-6)
    if abs(float(n @ u)) > 1e-6:
        raise ValueError(f"normal and axis_u must be orthogonal, got dot={float(n @ u):.3g}")
    R = np.empty((3, 3))
    R[:, 0] = n
    R[:, 1] = u
    n0, n1, n2 = n.tolist()
    u0, u1, u2 = u.tolist()
    R[:, 2] = (n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0)    # n × u (np.cross's products)
    return R


def clamp_half_span(stretch: float, size: float = geometry.SHEET_SIZE) -> float:
    """Half the clamp-to-clamp distance a = size·(1 + stretch)/2, m, for the unstretched side ``size`` (m)
    and the engineering strain ``stretch`` (> −1). Cheap enough for the planner's per-update path.
    Raises ``ValueError`` for a non-finite or non-positive result."""
    a = 0.5 * size * (1.0 + stretch)
    if not (a > 0.0 and math.isfinite(a)):
        raise ValueError(f"stretch {stretch!r} and size {size!r} give no positive half span (need size > 0, "
                         f"stretch > -1)")
    return a


def stretch_of_span(half_span: float, size: float = geometry.SHEET_SIZE) -> float:
    """Engineering strain ε = 2a/size − 1 (clipped at 0: a slack sheet has no negative stretch) from the
    measured half span ``half_span`` a (m) and the unstretched side ``size`` (m); inverse of
    :func:`clamp_half_span`. Raises ``ValueError`` for non-positive or non-finite inputs."""
    a = check_positive("half_span", half_span)
    s = check_positive("size", size)
    return max(0.0, 2.0 * a / s - 1.0)


def clamp_points(origin: Sequence[float], axis_u: Sequence[float], stretch: float,
                 size: float = geometry.SHEET_SIZE) -> tuple[tuple[float, float, float],
                                                             tuple[float, float, float]]:
    """Left and right clamp points (3,) m: ``origin ± a·axis_u`` with a = :func:`clamp_half_span`.

    ``origin`` (3,) m and ``axis_u`` (3,) unit, any float sequences (plain tuples on the planner's hot path,
    no validation beyond the half span's); returns two float tuples (left at +axis_u)."""
    a = clamp_half_span(stretch, size)
    o0, o1, o2 = origin
    u0, u1, u2 = axis_u
    return (a * u0 + o0, a * u1 + o1, a * u2 + o2), (-a * u0 + o0, -a * u1 + o1, -a * u2 + o2)


def clamp_poses(origin, normal, axis_u, stretch: float,
                size: float = geometry.SHEET_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Left and right clamp poses T_display_clamp (4, 4) for a sheet centred at ``origin`` (3,) m.

    Rotation :func:`sheet_rotation` (normal, axis_u); positions :func:`clamp_points`, i.e. the clamped edges
    at ``origin ± size·(1 + stretch)/2 · axis_u`` (left at +axis_u). ``stretch`` is the engineering strain
    between the clamps (≥ 0), ``size`` the unstretched side (m). Raises ``ValueError`` on bad vectors or a
    negative stretch.
    """
    if not (stretch >= 0.0 and math.isfinite(stretch)):
        raise ValueError(f"stretch must be finite and >= 0, got {stretch!r}")
    R = sheet_rotation(normal, axis_u)
    o = check_point("origin", origin)
    out = []
    for p in clamp_points(o, R[:, 1], stretch, size):
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p
        out.append(T)
    return out[0], out[1]


def frame_from_clamps(T_left, T_right) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Sheet frame from the two measured clamp poses T_display_clamp (4, 4): (origin (3,) m, normal (3,),
    axis_u (3,), half span a m). Inverse of :func:`clamp_poses`.

    origin = midpoint of the clamp positions, axis_u = unit(p_left − p_right), normal = mean of the clamps'
    first columns made orthogonal to axis_u, a = |p_left − p_right| / 2. Raises ``ValueError`` for poses
    that are not rigid transforms (:func:`flexsheet.model.checks.check_pose`, naming ``T_left``/``T_right``),
    clamps closer than 1 mm, or clamp normals more than 90° apart.
    """
    Tl = check_pose("T_left", T_left, tol=_POSE_TOL)
    Tr = check_pose("T_right", T_right, tol=_POSE_TOL)
    pl, pr = Tl[:3, 3], Tr[:3, 3]
    span = float(np.linalg.norm(pl - pr))
    if span < 1e-3:
        raise ValueError(f"clamps must be at least 1 mm apart, got {span!r} m")
    eu = (pl - pr) / span
    if float(Tl[:3, 0] @ Tr[:3, 0]) <= 0.0:
        raise ValueError("clamp normals (first pose columns) point in opposite directions")
    n = Tl[:3, 0] + Tr[:3, 0]
    n = check_unit("normal", n - (n @ eu) * eu)
    return 0.5 * (pl + pr), n, eu, span / 2


# -- the series form of a pushed sheet (the Membrane's, and
# the renderer's fitted shapes, which the fine shader draws)
def neumann_green(v, mu, v0: float, b: float, deriv: bool = False):
    """Neumann Green's function G(v; μ, v0) of g'' − μ²g = −δ(v − v0) on [−b, b] (zero slope at ±b), and
    dG/dv, for v (N,) m (clamped to [−b, b]) and μ (K,) 1/m: (N, K) arrays, in the overflow-free exponential
    form ``cosh(μ(b + v<)) cosh(μ(b − v>)) / (μ sinh 2μb)`` that float32 GLSL also evaluates."""
    v = np.clip(np.asarray(v, float), -b, b)[:, None]
    mu = np.asarray(mu, float)[None, :]
    lo, hi = np.minimum(v, v0), np.maximum(v, v0)
    ex = np.exp(-2.0 * mu * (b + lo))
    ey = np.exp(-2.0 * mu * (b - hi))
    e = np.exp(-mu * (hi - lo))
    den = 2.0 * (1.0 - np.exp(-4.0 * mu * b))
    g = e * (1.0 + ex) * (1.0 + ey) / (mu * den)
    if not deriv:
        return g
    # v is the upper argument: d/dv cosh(mu(b - v)) = -mu sinh(mu(b - v))
    dg = np.where(v >= v0, -e * (1.0 + ex) * (1.0 - ey) / den, e * (1.0 - ex) * (1.0 + ey) / den)
    return g, dg


def series_deflection(u, v, lam, mu, coef, a: float, b: float, v0: float):
    """(w, ∂w/∂u, ∂w/∂v) of w = Σ_i coef_i sin(lam_i (u + a)) G(v; mu_i, v0) at (u, v) m (broadcast; clamped
    onto
    |u| ≤ a, |v| ≤ b), each of the broadcast shape; ``lam``, ``mu``, ``coef`` (K,)."""
    u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
    shape = u.shape
    uu = np.clip(u.ravel(), -a, a)[:, None]
    ph = lam * (uu + a)
    s, c = np.sin(ph), np.cos(ph) * lam
    g, dg = neumann_green(v.ravel(), mu, v0, b, deriv=True)
    w = (coef * s * g).sum(axis=1)
    wu = (coef * c * g).sum(axis=1)
    wv = (coef * s * dg).sum(axis=1)
    return w.reshape(shape), wu.reshape(shape), wv.reshape(shape)


# -- pushed membrane -----------------------------------------------------------------------------------
class DeflectionGrid:
    """Mixin of every pushed-sheet shape (:class:`Membrane`, :class:`flexsheet.model.sheet_table.FemShape`,
    the renderer's ``SeriesShape``): :meth:`grid` from the shape's ``half_span`` a, ``half_width`` b (m) and
    ``deflection(u, v)``."""

    def grid(self, n: int) -> np.ndarray:
        """Deflection sampled on an n×n grid over u ∈ [−a, a] (rows) × v ∈ [−b, b] (columns), m, shape (n, n).

        This is the layout of :class:`messages.SheetState` ``membrane`` (index [i, j] ↔ u_i, v_j). Raises
        ``ValueError`` for n < 2."""
        if n < 2:
            raise ValueError(f"n must be >= 2, got {n!r}")
        u = np.linspace(-self.half_span, self.half_span, n)
        v = np.linspace(-self.half_width, self.half_width, n)
        return self.deflection(u[:, None], v[None, :])


@dataclass(frozen=True)
class Membrane(DeflectionGrid):
    """Deflection ``w(u, v)`` (m, along ``-normal``) of the pushed sheet in its own (u, v) frame.

    Parameters (all SI): ``half_span`` a (m, clamps at u = ±a), ``half_width`` b (m, free edges at v = ±b),
    ``push_u``, ``push_v`` (m, pushed point, must lie inside the sheet), ``depth`` S (m, ≥ 0),
    ``tension_ratio`` beta = T_v / T_u (> 0), ``contact_radius`` r (m, > 0), ``modes`` K (≥ 1).
    Raises ``ValueError`` naming the field for non-finite, non-positive or out-of-sheet values.
    Source: membrane equation with the boundary conditions and load described in the module docstring.
    """

    half_span: float
    half_width: float
    push_u: float = 0.0
    push_v: float = 0.0
    depth: float = 0.0
    tension_ratio: float = 1.0
    contact_radius: float = 0.008
    modes: int = TRUE_MODES
    lam: np.ndarray = field(init=False, repr=False, compare=False)
    mu: np.ndarray = field(init=False, repr=False, compare=False)
    coef: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        a = check_positive("half_span", self.half_span)
        b = check_positive("half_width", self.half_width)
        check_positive("tension_ratio", self.tension_ratio)
        r = check_positive("contact_radius", self.contact_radius)
        if not isinstance(self.modes, (int, np.integer)) or self.modes < 1:
            raise ValueError(f"modes must be an int >= 1, got {self.modes!r}")
        for name in ("push_u", "push_v", "depth"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.depth < 0.0:
            raise ValueError(f"depth must be >= 0, got {self.depth!r}")
        if abs(self.push_u) >= a or abs(self.push_v) > b:
            raise ValueError(f"pushed point (push_u, push_v)=({self.push_u!r}, {self.push_v!r}) lies outside "
                             f"the sheet |u| < {a}, |v| <= {b}")
        k = np.arange(1, int(self.modes) + 1, dtype=float)
        lam = k * math.pi / (2.0 * a)
        mu = lam / math.sqrt(self.tension_ratio)
        q = np.sin(lam * (self.push_u + a)) * np.sinc(lam * r / math.pi)
        object.__setattr__(self, "lam", lam)
        object.__setattr__(self, "mu", mu)
        raw = q * np.sin(lam * (self.push_u + a)) * self._green(np.array([self.push_v]))[0]
        peak = float(raw.sum())
        coef = q * (self.depth / peak) if peak > 0.0 else np.zeros_like(q)
        object.__setattr__(self, "coef", coef)

    # -- Green's function in v, overflow-free form ---------------------------------------------------------
    def _green(self, v: np.ndarray, deriv: bool = False):
        """G_k(v, v0) (and dG/dv) for v of shape (N,), returns (N, K) arrays (:func:`neumann_green`)."""
        return neumann_green(v, self.mu, self.push_v, self.half_width, deriv)

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m (positive along −normal). ``u``, ``v`` broadcastable arrays in m (sheet frame);
        points outside the sheet are clamped onto its boundary. Returns an array of the broadcast shape."""
        return self.deflection_grad(u, v)[0]

    def deflection_grad(self, u, v):
        """(w, ∂w/∂u, ∂w/∂v) at (u, v) (m, m/m, m/m), same broadcast shape as the inputs; see
        ``deflection``."""
        return series_deflection(u, v, self.lam, self.mu, self.coef, self.half_span, self.half_width,
                                 self.push_v)



@dataclass(frozen=True)
class SheetSurface:
    """The actual sheet: a plane pose plus an optional membrane deflection (display frame, m).

    ``origin`` (3,) sheet centre (midpoint of the clamps), ``normal`` (3,) toward the user, ``axis_u`` (3,)
    right → left clamp; ``half_span`` a and ``half_width`` b (m) bound the sheet (|u| ≤ a, |v| ≤ b);
    ``membrane`` (or None for a flat sheet) gives the deflection along −normal — a :class:`Membrane` or any
    object with its interface (``push_u``, ``push_v``, ``depth``, ``deflection``, ``deflection_grad``,
    ``grid``), e.g. the twin's true FEM shape :class:`flexsheet.model.sheet_table.FemShape`; ``size`` (m) is
    the unstretched side between the clamps (for :attr:`stretch`). Raises ``ValueError`` on non-finite, zero
    or non-orthogonal vectors and non-positive lengths (error names the field).
    """

    origin: np.ndarray
    normal: np.ndarray
    axis_u: np.ndarray
    half_span: float = geometry.SHEET_SIZE / 2
    half_width: float = geometry.SHEET_SIZE / 2
    membrane: Membrane | None = None          # or a FemShape (same interface)
    size: float = geometry.SHEET_SIZE

    def __post_init__(self) -> None:
        o = check_point("origin", self.origin)
        n = check_unit("normal", self.normal)
        u = check_unit("axis_u", self.axis_u)
        if abs(float(n @ u)) > 1e-6:
            raise ValueError(f"normal and axis_u must be orthogonal, got dot={float(n @ u):.3g}")
        check_positive("half_span", self.half_span)
        check_positive("half_width", self.half_width)
        check_positive("size", self.size)
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "axis_u", u)

    @property
    def stretch(self) -> float:
        """Engineering strain between the clamps, :func:`stretch_of_span` (half_span, size) (≥ 0)."""
        return stretch_of_span(self.half_span, self.size)

    @property
    def axis_v(self) -> np.ndarray:
        """axis_v = normal × axis_u (+z at home), (3,)."""
        return np.cross(self.normal, self.axis_u)

    @property
    def corners(self) -> np.ndarray:
        """(4, 3) corners in order around the sheet: (+u,+v), (−u,+v), (−u,−v), (+u,−v), m."""
        a, b, eu, ev = self.half_span, self.half_width, self.axis_u, self.axis_v
        return np.array([self.origin + su * a * eu + sv * b * ev for su,
                         sv in ((1, 1), (-1, 1), (-1, -1), (1, -1))])

    @property
    def pushed_point(self) -> np.ndarray:
        """Deepest point of the depression (the origin's projection when not pushed), (3,) m."""
        if self.membrane is None:
            return self.origin.copy()
        m = self.membrane
        return self.origin + m.push_u * self.axis_u + m.push_v * self.axis_v - m.depth * self.normal

    def point(self, u, v) -> np.ndarray:
        """Surface point for sheet coordinates u, v (arrays, m) → (..., 3) m."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        w = (self.membrane.deflection(u, v) if self.membrane is not None
             else np.zeros(np.broadcast(u, v).shape))
        return (self.origin + u[..., None] * self.axis_u + v[..., None] * self.axis_v
                - w[..., None] * self.normal)

    @classmethod
    def from_clamps(cls, T_left: np.ndarray, T_right: np.ndarray, *,
                    half_width: float = geometry.SHEET_SIZE / 2,
                    pushed_point: np.ndarray | None = None, membrane_kwargs: dict | None = None,
                    size: float = geometry.SHEET_SIZE) -> SheetSurface:
        """Sheet from the two measured clamp poses T_display_clamp (4, 4) (convention of
        :mod:`flexsheet.model.geometry`).

        The frame comes from :func:`frame_from_clamps`. If ``pushed_point`` (3,) lies behind the plane
        (depth > 0) and inside the sheet, a :class:`Membrane` with that depth is attached (``membrane_kwargs``
        forwarded, e.g. ``modes``). ``size`` (m): unstretched side between the clamps, for :attr:`stretch`.
        Raises ``ValueError`` for non-rigid or non-finite poses (naming ``T_left``/``T_right``), clamps closer
        than 1 mm, normals that do not agree (clamp normals more than 90° apart) or a bad ``pushed_point``.
        """
        origin, n, eu, a = frame_from_clamps(T_left, T_right)
        mem = None
        if pushed_point is not None:
            d = check_point("pushed_point", pushed_point) - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            if depth > 0.0 and abs(pu) < a and abs(pv) <= half_width:
                mem = Membrane(a, half_width, pu, pv, depth, **(membrane_kwargs or {}))
        return cls(origin, n, eu, a, half_width, mem, size)
