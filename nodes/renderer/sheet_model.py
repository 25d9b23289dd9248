"""The renderer's nominal pushed-sheet model: the nonlinear membrane FEM solved with the sheet's NOMINAL
material, fitted into the "fine" shader's series form (pure: numpy; the FEM from :mod:`flexsheet.model.sheet_fem`).

Why: the fine correction's sine-series membrane (:class:`flexsheet.model.sheet.Membrane`, small-slope,
tension ratio 1) is linear; a 1 mm urethane sheet pushed 10–50 mm is not — the push stretches it, the dent
becomes conical, and the series is 0.8 mm off at 10 mm and ~11 mm off at 50 mm where the object's outline is
seen (measured on the twin, docs/renderer.md). This module keeps the shader and replaces the shape it is given:

1. **Table** (:meth:`NominalSheetModel.table`): :class:`flexsheet.model.sheet_fem.IndentTable` of
   :class:`flexsheet.model.sheet_fem.SheetPhysics` with what the estimator knows — the clamp span measured by
   the arms (rounded to a ``stretch_step`` node), the sheet's NOMINAL Young's modulus and size
   (:class:`flexsheet.model.tension.SheetMaterial`), no pre-strain, and an ASSUMED tension ratio (default 1).
   Never the twin's truth: the truth's E (±15 %), pre-strain (|N(0, 0.5 %)|) and tension ratio (±20 %) differ
   from these (:mod:`flexsheet.model.truth`); under ``realism: ideal`` they coincide and the model is in-model
   (an inverse crime, stated wherever that column is reported). Solved once per stretch node (~3 s per
   contact position on one core) and cached on disk.
2. **Fit** (:meth:`NominalSheetModel.shape`): the table's shape at the measured depth and contact, sampled on
   a grid, is projected on the clamped sine modes ``sin(λ_k (u + a))``, λ_k = kπ/2a (exact for the clamped
   edges u = ±a); the ``n_modes`` modes with the most energy are kept, and each mode's profile across the
   sheet is fitted by least squares with ``len(mu_scales)`` Neumann Green's functions of the shader
   (decay μ = λ_k·s for s in ``mu_scales``, centred on the contact, zero slope at the free edges v = ±b).
   The result, a :class:`SeriesShape` of n_modes·len(mu_scales) ≤ 64 terms, is evaluated exactly like
   :class:`flexsheet.model.sheet.Membrane` (same λ, μ, coef arrays), so the GLSL fine model draws it
   unchanged. Fits are cached (LRU) on the contact rounded to 0.1 mm.

Units: m, sheet frame (u along axis_u, v along axis_v, w along −normal), as :mod:`flexsheet.model.sheet`.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from flexsheet.model import scene
from flexsheet.model.sheet import SheetSurface, clamp_half_span, stretch_of_span
from flexsheet.model.sheet_fem import TABLE_POSITIONS, IndentTable, SheetPhysics, default_cache_dir
from flexsheet.model.tension import SheetMaterial, tension

__all__ = ["SeriesShape", "NominalSheetModel", "MODEL_DEPTHS", "green"]

#: depths (m) of the nominal table (the fit interpolates between them)
MODEL_DEPTHS = (0.005, 0.010, 0.020, 0.030, 0.040, 0.050, 0.060)
#: most terms the fine shader evaluates (``nodes.renderer.scene.MAX_SHADER_MODES``)
MAX_TERMS = 64


def green(v: np.ndarray, mu: np.ndarray, v0: float, b: float, deriv: bool = False):
    """Neumann Green's function G(v; μ, v0) of g'' − μ²g = −δ(v − v0) on [−b, b] (and dG/dv), for v (N,) and μ
    (K,): (N, K) arrays, in the overflow-free form of :class:`flexsheet.model.sheet.Membrane` and the shader."""
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
    dg = np.where(v >= v0, -e * (1.0 + ex) * (1.0 - ey) / den, e * (1.0 - ex) * (1.0 + ey) / den)
    return g, dg


@dataclass(frozen=True)
class SeriesShape:
    """A pushed-sheet deflection in the fine shader's form, w(u, v) = Σ_i coef_i sin(lam_i (u + a)) G(v; mu_i,
    push_v) (m, along −normal), the interface of :class:`flexsheet.model.sheet.Membrane` (``half_span`` a,
    ``half_width`` b, ``push_u``, ``push_v``, ``depth`` m; ``lam``, ``mu``, ``coef`` (K,); :meth:`deflection`,
    :meth:`deflection_grad`, :meth:`grid`), so a :class:`SheetSurface` can carry it and
    :meth:`nodes.renderer.scene.StereoRenderer.set_model` sends it to the shader. ``source``: one line saying
    what it was fitted to; ``fit_rms`` m: rms residual of the fit on its grid."""

    half_span: float
    half_width: float
    push_u: float
    push_v: float
    depth: float
    lam: np.ndarray = field(repr=False)
    mu: np.ndarray = field(repr=False)
    coef: np.ndarray = field(repr=False)
    source: str = ""
    fit_rms: float = 0.0

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m; ``u``, ``v`` broadcastable (m, sheet frame, clamped onto the sheet)."""
        return self.deflection_grad(u, v)[0]

    def deflection_grad(self, u, v):
        """(w, ∂w/∂u, ∂w/∂v) at (u, v), broadcast shape of the inputs."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        shape = u.shape
        a = self.half_span
        uu = np.clip(u.ravel(), -a, a)[:, None]
        ph = self.lam * (uu + a)
        s, c = np.sin(ph), np.cos(ph) * self.lam
        g, dg = green(v.ravel(), self.mu, self.push_v, self.half_width, deriv=True)
        w = (self.coef * s * g).sum(axis=1)
        wu = (self.coef * c * g).sum(axis=1)
        wv = (self.coef * s * dg).sum(axis=1)
        return w.reshape(shape), wu.reshape(shape), wv.reshape(shape)

    def grid(self, n: int) -> np.ndarray:
        """(n, n) deflection on u ∈ [−a, a] (rows) × v ∈ [−b, b] (columns), the ``SheetState.membrane`` layout."""
        if n < 2:
            raise ValueError(f"n must be >= 2, got {n!r}")
        u = np.linspace(-self.half_span, self.half_span, n)
        v = np.linspace(-self.half_width, self.half_width, n)
        return self.deflection(u[:, None], v[None, :])


def fit_series(w_grid: np.ndarray, a: float, b: float, push_u: float, push_v: float, depth: float,
               n_modes: int = 16, mu_scales=(0.4, 0.7, 1.0, 1.6), max_k: int = 64, source: str = "") -> SeriesShape:
    """Fit a deflection sampled on a grid (nu, nv) over u ∈ [−a, a] × v ∈ [−b, b] (m) with the shader's series
    (module doc, step 2). Raises ``ValueError`` when n_modes·len(mu_scales) exceeds :data:`MAX_TERMS` or the
    grid is too coarse (nu < 2·max_k + 1, nv < 2·len(mu_scales))."""
    W = np.asarray(w_grid, float)
    nu, nv = W.shape
    J = len(mu_scales)
    if n_modes < 1 or n_modes * J > MAX_TERMS:
        raise ValueError(f"n_modes × len(mu_scales) must be in 1..{MAX_TERMS}, got {n_modes} × {J}")
    if nu < 2 * max_k + 1 or nv < 2 * J:
        raise ValueError(f"grid {nu}×{nv} too coarse for {max_k} modes and {J} decay rates")
    u = np.linspace(-a, a, nu)
    v = np.linspace(-b, b, nv)
    wts = np.full(nu, u[1] - u[0])
    wts[[0, -1]] *= 0.5
    k = np.arange(1, max_k + 1)
    lam_all = k * math.pi / (2.0 * a)
    Phi = np.sin(lam_all[:, None] * (u[None, :] + a))           # (max_k, nu)
    F = (Phi * wts) @ W / a                                      # sine coefficients per v, (max_k, nv)
    keep = np.sort(np.argsort(-(F ** 2).sum(axis=1))[:n_modes])
    lam, mu, coef = [], [], []
    R = np.zeros_like(W)
    for i in keep:
        mus = lam_all[i] * np.asarray(mu_scales, float)
        B = green(v, mus, push_v, b)                             # (nv, J)
        c = np.linalg.lstsq(B, F[i], rcond=None)[0]
        lam += [lam_all[i]] * J
        mu += list(mus)
        coef += list(c)
        R += Phi[i][:, None] * (B @ c)[None, :]
    rms = float(np.sqrt(np.mean((R - W) ** 2)))
    return SeriesShape(float(a), float(b), float(push_u), float(push_v), float(depth), np.array(lam), np.array(mu),
                       np.array(coef), source, rms)


class NominalSheetModel:
    """The pushed sheet as the renderer models it: nominal FEM tables per stretch node, fitted into the shader's
    series (module doc). ``material``: nominal sheet (:class:`SheetMaterial`); ``tension_ratio``: assumed
    T_v/T_u; ``prestrain``: assumed pre-strain (0); ``stretch_step``: spacing of the table nodes; ``depths``,
    ``positions`` (m) and ``mesh``: the tables (:class:`IndentTable`); ``cache_dir``: where they are cached
    (default :func:`flexsheet.model.sheet_fem.default_cache_dir`); ``n_modes``, ``mu_scales``: the fit;
    ``grid``: (nu, nv) samples of the fit; ``progress``: callable(str) for table builds. Raises ``ValueError``
    on a bad setting."""

    def __init__(self, material: SheetMaterial | None = None, *, tension_ratio: float = 1.0, prestrain: float = 0.0,
                 stretch_step: float = 0.01, depths=MODEL_DEPTHS, positions=TABLE_POSITIONS, mesh: dict | None = None,
                 cache_dir: str | None = None, n_modes: int = 16, mu_scales=(0.4, 0.7, 1.0, 1.6),
                 grid: tuple[int, int] = (193, 121), progress=None, cache_size: int = 256) -> None:
        self.material = material or SheetMaterial()
        for k, v in (("tension_ratio", tension_ratio), ("stretch_step", stretch_step)):
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{k} must be finite and > 0, got {v!r}")
        if not (math.isfinite(prestrain) and prestrain >= 0.0):
            raise ValueError(f"prestrain must be finite and >= 0, got {prestrain!r}")
        if n_modes * len(mu_scales) > MAX_TERMS or n_modes < 1:
            raise ValueError(f"n_modes × len(mu_scales) must be in 1..{MAX_TERMS}, got {n_modes} × {len(mu_scales)}")
        self.tension_ratio, self.prestrain, self.stretch_step = float(tension_ratio), float(prestrain), float(stretch_step)
        self.depths, self.positions = tuple(depths), tuple(positions)
        self.mesh = dict(mesh or {})
        self.cache_dir = cache_dir or default_cache_dir()
        self.n_modes, self.mu_scales, self.grid_n = int(n_modes), tuple(float(s) for s in mu_scales), tuple(grid)
        self.progress = progress
        self._tables: dict[float, IndentTable] = {}
        self._fits: OrderedDict = OrderedDict()
        self._cache_size = int(cache_size)

    @classmethod
    def nominal(cls, stretch: float | None = None, progress=None, **kw) -> NominalSheetModel:
        """The default model; with ``stretch``, its table at that node is built (or loaded) now."""
        m = cls(progress=progress, **kw)
        if stretch is not None:
            m.table(m.node_of(stretch))
        return m

    def node_of(self, stretch: float) -> float:
        """The table node (clamp strain) nearest ``stretch``, at least one step (the planner never leaves the
        sheet slack: ``SheetMaterial.min_stretch`` = 0.01; an unstretched membrane has no pre-tension)."""
        st = self.stretch_step
        return round(max(st, round(float(stretch) / st) * st), 6)

    def physics(self, node: float) -> SheetPhysics:
        """Nominal physics at clamp strain ``node``: E and size of ``material``, T_u = tension(node + prestrain),
        the assumed tension ratio."""
        size = self.material.size
        return SheetPhysics(half_span=clamp_half_span(node, size), half_width=size / 2, young=self.material.young,
                            thickness=self.material.thickness,
                            tension_u=tension(node + self.prestrain, self.material), tension_ratio=self.tension_ratio)

    def table(self, node: float) -> IndentTable:
        """The nominal table at ``node`` (built once, cached on disk)."""
        if node not in self._tables:
            ph = self.physics(node)
            if ph.tension_u <= 0.0:
                raise ValueError(f"no tension at stretch {node!r}: the nominal model needs a stretched sheet")
            self._tables[node] = IndentTable(ph, self.depths, self.positions, mesh=self.mesh, cache_dir=self.cache_dir,
                                             progress=self.progress)
        return self._tables[node]

    def shape(self, half_span: float, depth: float, push_u: float, push_v: float,
              half_width: float = scene.SHEET_SIZE / 2) -> SeriesShape:
        """The fitted pushed shape for the measured clamp half span (m), depth (m, > 0) and contact (m)."""
        if not (math.isfinite(depth) and depth > 0.0):
            raise ValueError(f"depth must be finite and > 0, got {depth!r}")
        node = self.node_of(stretch_of_span(half_span, self.material.size))
        key = (node, round(half_span, 5), round(depth, 4), round(push_u, 4), round(push_v, 4), round(half_width, 5))
        hit = self._fits.get(key)
        if hit is not None:
            self._fits.move_to_end(key)
            return hit
        tab = self.table(node)
        nu, nv = self.grid_n
        u = np.linspace(-half_span, half_span, nu)
        v = np.linspace(-half_width, half_width, nv)
        W = tab.evaluate(depth, push_u, push_v, u[:, None], v[None, :], half_span)
        src = (f"nominal FEM (E {self.material.young / 1e6:.2f} MPa, pre-strain {self.prestrain:g}, tension ratio "
               f"{self.tension_ratio:g}, stretch node {node:g}), {self.n_modes}×{len(self.mu_scales)} terms")
        out = fit_series(W, half_span, half_width, push_u, push_v, depth, self.n_modes, self.mu_scales, source=src)
        self._fits[key] = out
        if len(self._fits) > self._cache_size:
            self._fits.popitem(last=False)
        return out

    def surface(self, sheet: SheetSurface) -> SheetSurface:
        """``sheet`` with its membrane (the measured depth and contact) replaced by this model's shape; a flat
        sheet is returned as is."""
        m = sheet.membrane
        if m is None or m.depth <= 0.0:
            return sheet
        return replace(sheet, membrane=self.shape(sheet.half_span, m.depth, m.push_u, m.push_v, sheet.half_width))

    def describe(self) -> dict:
        """JSON-able description (for reports)."""
        return {"name": "fem_nominal", "young_Pa": self.material.young, "prestrain": self.prestrain,
                "tension_ratio": self.tension_ratio, "stretch_step": self.stretch_step, "depths_m": list(self.depths),
                "positions_m": list(self.positions), "mesh": self.mesh, "n_modes": self.n_modes,
                "mu_scales": list(self.mu_scales), "terms": self.n_modes * len(self.mu_scales),
                "note": "nominal material and assumed tension ratio; never the truth's"}
