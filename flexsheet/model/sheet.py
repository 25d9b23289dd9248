"""Shape of the pushed sheet: a pre-tensioned membrane clamped on two edges, free on two, pushed by a finger.

Model (stated here because the paper does not give one; §III-C only says "exact correction requires accurate
measurement of the shape of the sheet"):

* Small-slope membrane under uniform in-plane tension: ``T_u w_uu + T_v w_vv = -p(u, v)`` for the
  out-of-plane deflection ``w`` (m, positive along ``-normal``, i.e. away from the user). Bending of the 1 mm
  rubber is neglected (membrane limit; Timoshenko & Woinowsky-Krieger, *Theory of Plates and Shells*, §1 and
  the membrane equation of Love), as is the extra tension the push itself adds (it is folded into ``T_u``,
  ``T_v``; only their ratio ``beta = T_v / T_u`` matters for the shape).
* Boundary conditions in the sheet frame (``u`` along ``axis_u``, ``v`` along ``axis_v``, see
  :mod:`flexsheet.model.scene`): Dirichlet ``w = 0`` on the clamped edges ``u = ±a`` (the arms' clamps), and
  zero transverse force ``∂w/∂v = 0`` on the free edges ``v = ±b``.
* Load: the fingertip presses a short segment ``|u - u0| ≤ r``, ``v = v0`` (``r`` = contact radius) with
  unknown force; the force is fixed by the measured depth: ``w(u0, v0) = S``. A point load would give the
  logarithmic singularity of the 2-D Green's function; the finite contact keeps the depth finite.
* Solution: sine series in ``u`` (modes ``φ_k(u) = sin(λ_k (u + a))``, ``λ_k = kπ / 2a``) times the 1-D
  Neumann Green's function in ``v`` of ``g'' − μ_k² g = −δ`` (``μ_k = λ_k / √beta``):
  ``G_k(v, v0) = cosh(μ(b + v<)) cosh(μ(b − v>)) / (μ sinh 2μb)``, evaluated in an overflow-free
  exponential form (also used by the GLSL fine model). ``w = c Σ_k q_k φ_k(u) G_k(v, v0)`` with
  ``q_k = φ_k(u0) sinc(λ_k r)`` (the exact modal projection of the segment load) and ``c`` chosen so that
  ``w(u0, v0) = S``.

``modes`` sets the truncation: the series converges like ``Σ 1/k²`` beyond ``k ≈ 2a / r``; 256 modes is
the reference ("true") shape used by the measurement camera and the world; the renderer's fine correction
uses a cheap fit of the same shape with fewer modes (see docs/renderer.md for the error this costs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model import scene

__all__ = ["Membrane", "SheetSurface", "TRUE_MODES"]

#: number of modes of the reference ("true") membrane shape
TRUE_MODES = 256


def _check_pos(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


@dataclass(frozen=True)
class Membrane:
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
        a = _check_pos("half_span", self.half_span)
        b = _check_pos("half_width", self.half_width)
        _check_pos("tension_ratio", self.tension_ratio)
        r = _check_pos("contact_radius", self.contact_radius)
        if not isinstance(self.modes, (int, np.integer)) or self.modes < 1:
            raise ValueError(f"modes must be an int >= 1, got {self.modes!r}")
        for name in ("push_u", "push_v", "depth"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.depth < 0.0:
            raise ValueError(f"depth must be >= 0, got {self.depth!r}")
        if abs(self.push_u) >= a or abs(self.push_v) > b:
            raise ValueError(f"pushed point (push_u, push_v)=({self.push_u!r}, {self.push_v!r}) lies outside the "
                             f"sheet |u| < {a}, |v| <= {b}")
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
        """G_k(v, v0) (and dG/dv) for v of shape (N,), returns (N, K) arrays."""
        b, v0, mu = self.half_width, self.push_v, self.mu[None, :]
        v = np.clip(v, -b, b)[:, None]
        lo = np.minimum(v, v0)
        hi = np.maximum(v, v0)
        ex = np.exp(-2.0 * mu * (b + lo))
        ey = np.exp(-2.0 * mu * (b - hi))
        e = np.exp(-mu * (hi - lo))
        den = 2.0 * (1.0 - np.exp(-4.0 * mu * b))
        g = e * (1.0 + ex) * (1.0 + ey) / (mu * den)
        if not deriv:
            return g
        above = v >= v0  # v is the upper argument: d/dv cosh(mu(b - v)) = -mu sinh(mu(b - v))
        dg = np.where(above, -e * (1.0 + ex) * (1.0 - ey) / den, e * (1.0 - ex) * (1.0 + ey) / den)
        return g, dg

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m (positive along −normal). ``u``, ``v`` broadcastable arrays in m (sheet frame);
        points outside the sheet are clamped onto its boundary. Returns an array of the broadcast shape."""
        return self.deflection_grad(u, v)[0]

    def deflection_grad(self, u, v):
        """(w, ∂w/∂u, ∂w/∂v) at (u, v) (m, m/m, m/m), same broadcast shape as the inputs; see ``deflection``."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        shape = u.shape
        a = self.half_span
        uu = np.clip(u.ravel(), -a, a)[:, None]
        s = np.sin(self.lam * (uu + a))
        c = np.cos(self.lam * (uu + a)) * self.lam
        g, dg = self._green(v.ravel(), deriv=True)
        w = (self.coef * s * g).sum(axis=1)
        wu = (self.coef * c * g).sum(axis=1)
        wv = (self.coef * s * dg).sum(axis=1)
        return w.reshape(shape), wu.reshape(shape), wv.reshape(shape)

    def grid(self, n: int) -> np.ndarray:
        """Deflection sampled on an n×n grid over u ∈ [−a, a] (rows) × v ∈ [−b, b] (columns), m, shape (n, n).

        This is the layout of :class:`messages.SheetState` ``membrane`` (index [i, j] ↔ u_i, v_j)."""
        if n < 2:
            raise ValueError(f"n must be >= 2, got {n!r}")
        u = np.linspace(-self.half_span, self.half_span, n)
        v = np.linspace(-self.half_width, self.half_width, n)
        return self.deflection(u[:, None], v[None, :])


def _unit(name: str, v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite (3,) vector, got {v!r}")
    nrm = float(np.linalg.norm(v))
    if nrm < 1e-12:
        raise ValueError(f"{name} must be non-zero, got {v!r}")
    return v / nrm


@dataclass(frozen=True)
class SheetSurface:
    """The actual sheet: a plane pose plus an optional membrane deflection (display frame, m).

    ``origin`` (3,) sheet centre (midpoint of the clamps), ``normal`` (3,) toward the user, ``axis_u`` (3,)
    right → left clamp; ``half_span`` a and ``half_width`` b (m) bound the sheet (|u| ≤ a, |v| ≤ b);
    ``membrane`` (or None for a flat sheet) gives the deflection along −normal. Raises ``ValueError`` on
    non-finite, zero or non-orthogonal vectors (error names the field).
    """

    origin: np.ndarray
    normal: np.ndarray
    axis_u: np.ndarray
    half_span: float = scene.SHEET_SIZE / 2
    half_width: float = scene.SHEET_SIZE / 2
    membrane: Membrane | None = None

    def __post_init__(self) -> None:
        o = np.asarray(self.origin, dtype=float)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f"origin must be a finite (3,) vector, got {o!r}")
        n = _unit("normal", self.normal)
        u = _unit("axis_u", self.axis_u)
        if abs(float(n @ u)) > 1e-6:
            raise ValueError(f"normal and axis_u must be orthogonal, got dot={float(n @ u):.3g}")
        _check_pos("half_span", self.half_span)
        _check_pos("half_width", self.half_width)
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "axis_u", u)

    @property
    def axis_v(self) -> np.ndarray:
        """axis_v = normal × axis_u (+z at home), (3,)."""
        return np.cross(self.normal, self.axis_u)

    @property
    def corners(self) -> np.ndarray:
        """(4, 3) corners in order around the sheet: (+u,+v), (−u,+v), (−u,−v), (+u,−v), m."""
        a, b, eu, ev = self.half_span, self.half_width, self.axis_u, self.axis_v
        return np.array([self.origin + su * a * eu + sv * b * ev for su, sv in ((1, 1), (-1, 1), (-1, -1), (1, -1))])

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
        w = self.membrane.deflection(u, v) if self.membrane is not None else np.zeros(np.broadcast(u, v).shape)
        return (self.origin + u[..., None] * self.axis_u + v[..., None] * self.axis_v - w[..., None] * self.normal)

    @classmethod
    def from_clamps(cls, T_left: np.ndarray, T_right: np.ndarray, *, half_width: float = scene.SHEET_SIZE / 2,
                    pushed_point: np.ndarray | None = None, membrane_kwargs: dict | None = None) -> SheetSurface:
        """Sheet from the two measured clamp poses T_display_clamp (4, 4) (convention of :mod:`flexsheet.model.scene`).

        origin = midpoint of the clamp positions, axis_u = unit(p_left − p_right), normal = mean of the
        clamps' first columns made orthogonal to axis_u, a = |p_left − p_right| / 2. If ``pushed_point`` (3,)
        lies behind the plane (depth > 0) and inside the sheet, a :class:`Membrane` with that depth is attached
        (``membrane_kwargs`` forwarded, e.g. ``modes``). Raises ``ValueError`` for non-finite poses, clamps
        closer than 1 mm, or normals that do not agree (clamp normals more than 90° apart).
        """
        Tl = np.asarray(T_left, dtype=float)
        Tr = np.asarray(T_right, dtype=float)
        for name, T in (("T_left", Tl), ("T_right", Tr)):
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                raise ValueError(f"{name} must be a finite (4, 4) pose, got {T!r}")
        pl, pr = Tl[:3, 3], Tr[:3, 3]
        span = float(np.linalg.norm(pl - pr))
        if span < 1e-3:
            raise ValueError(f"clamps must be at least 1 mm apart, got {span!r} m")
        eu = (pl - pr) / span
        n = Tl[:3, 0] + Tr[:3, 0]
        if float(Tl[:3, 0] @ Tr[:3, 0]) <= 0.0:
            raise ValueError("clamp normals (first pose columns) point in opposite directions")
        n = n - (n @ eu) * eu
        n = _unit("normal", n)
        origin = 0.5 * (pl + pr)
        mem = None
        if pushed_point is not None:
            p = np.asarray(pushed_point, dtype=float)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise ValueError(f"pushed_point must be a finite (3,) vector, got {p!r}")
            d = p - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            if depth > 0.0 and abs(pu) < span / 2 and abs(pv) <= half_width:
                mem = Membrane(span / 2, half_width, pu, pv, depth, **(membrane_kwargs or {}))
        return cls(origin, n, eu, span / 2, half_width, mem)
