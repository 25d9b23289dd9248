"""The display's nominal pushed-sheet model: the nonlinear membrane FEM solved with the sheet's NOMINAL
material, fitted into the renderer's "fine" shader's series form (pure: numpy; the FEM from
:mod:`flexsheet.model.sheet_fem`).

This is the display's only pushed-sheet shape: the renderer corrects its image for it (``RendererState``
attaches it to every push, :meth:`NominalSheetModel.pushed`) and the Foxglove bridge draws it as the sheet the
display believes in (:meth:`flexsheet.viz.scene_builder.SceneBuilder.believed_sheet`); both build it with
:func:`sheet_model_for` from the same :class:`SheetConfig`. Why: the old fine correction's sine-series membrane
(:class:`flexsheet.model.sheet.Membrane`, small-slope, tension ratio 1) is linear; a 1 mm urethane sheet pushed
10–50 mm is not — the push stretches it, the dent becomes conical, and the series is ~4 mm off at 50 mm where
the object's outline is seen (measured on the twin, docs/renderer.md). This module keeps the shader and
replaces the shape it is given:

1. **Table** (:meth:`NominalSheetModel.table`): :class:`flexsheet.model.sheet_table.IndentTable` of
   :class:`flexsheet.model.sheet_fem.SheetPhysics` with what the estimator knows — the clamp span measured by
   the arms (rounded to a ``stretch_step`` node), the sheet's NOMINAL Young's modulus and size
   (:class:`flexsheet.model.tension.SheetMaterial`), no pre-strain, and an ASSUMED tension ratio (default 1).
   Never the twin's truth: the truth's E (±15 %), pre-strain (|N(0, 0.5 %)|) and tension ratio (±20 %) differ
   from these (:mod:`flexsheet.twin.truth`); under ``realism: ideal`` they coincide and the model is in-model
   (an inverse crime, stated wherever that column is reported). Solved once per stretch node (~3 s per
   contact position on one core) and cached on disk.
2. **Fit** (:meth:`NominalSheetModel.shape`): the table's shape at the measured depth and contact, sampled on
   a grid, is projected on the clamped sine modes ``sin(λ_k (u + a))``, λ_k = kπ/2a (exact for the clamped
   edges u = ±a); the ``n_modes`` modes with the most energy are kept, and each mode's profile across the
   sheet is fitted by least squares with ``len(mu_scales)`` Neumann Green's functions of the shader
   (decay μ = λ_k·s for s in ``mu_scales``, centred on the contact, zero slope at the free edges v = ±b).
   The result, a :class:`SeriesShape` of n_modes·len(mu_scales) ≤ 64 terms, is evaluated exactly like
   :class:`flexsheet.model.sheet.Membrane` (same λ, μ, coef arrays), so the GLSL fine model draws it
   unchanged. Fits are cached (LRU) on the contact rounded to 0.1 mm. Per new fingertip the table on the fit
   grid (:func:`table_grid`) and the fit cost ~1–2 ms of CPU (``flexsheet bench render``).
3. **In the nodes**: :meth:`NominalSheetModel.shape` with ``build=False`` never builds a missing table in the
   caller's thread (a :class:`PendingPush` instead); the renderer node builds it in a worker process
   (:func:`flexsheet.rendering.state.build_table`), the bridge draws the push as 4 triangles meanwhile.

Units: m, sheet frame (u along axis_u, v along axis_v, w along −normal), as :mod:`flexsheet.model.sheet`.
"""

from __future__ import annotations

import logging
import math
import os
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from flexsheet.manifest import record
from flexsheet.model import geometry
from flexsheet.model.sheet import (
    DeflectionGrid,
    SheetSurface,
    clamp_half_span,
    series_deflection,
    stretch_of_span,
)
from flexsheet.model.sheet import neumann_green as green
from flexsheet.model.sheet_fem import SheetPhysics
from flexsheet.model.sheet_table import TABLE_POSITIONS, IndentTable, default_cache_dir
from flexsheet.model.tension import SheetMaterial, tension

log = logging.getLogger(__name__)

#: the nominal tables of the default settings at clamp strains 0.01–0.07 (what 40 N per clamp can hold), shipped
#: so that no display builds them while it runs (a table build beside the running graph slowed the loop:
#: flexsheet/runtime/background.py). Regenerate: ``python -m flexsheet.model.sheet_model --ship``.
SHIPPED_TABLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sheet_tables")

__all__ = ["SeriesShape", "PendingPush", "FourTriangleDent", "believed_sheet", "drawable", "NominalSheetModel",
           "MODEL_DEPTHS", "fit_series", "table_grid", "contact_of", "SheetConfig", "sheet_model_for",
           "ship_tables", "SHIPPED_TABLES"]

#: depths (m) of the nominal table (the fit interpolates between them)
MODEL_DEPTHS = (0.005, 0.010, 0.020, 0.030, 0.040, 0.050, 0.060)
#: most terms the fine shader evaluates (``flexsheet.rendering.stereo_renderer.MAX_SHADER_MODES``)
MAX_TERMS = 64


@dataclass(frozen=True)
class SeriesShape(DeflectionGrid):
    """A pushed-sheet deflection in the fine shader's form, w(u, v) = Σ_i coef_i sin(lam_i (u + a)) G(v; mu_i,
    push_v) (m, along −normal), the interface of :class:`flexsheet.model.sheet.Membrane` (``half_span`` a,
    ``half_width`` b, ``push_u``, ``push_v``, ``depth`` m; ``lam``, ``mu``, ``coef`` (K,); :meth:`deflection`,
    :meth:`deflection_grad`, :meth:`grid`), so a :class:`SheetSurface` can carry it and
    :meth:`flexsheet.rendering.stereo_renderer.StereoRenderer.set_model` sends it to the shader. ``source``: one line saying
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
        """(w, ∂w/∂u, ∂w/∂v) at (u, v), broadcast shape of the inputs (:func:`flexsheet.model.sheet.series_deflection`)."""
        return series_deflection(u, v, self.lam, self.mu, self.coef, self.half_span, self.half_width, self.push_v)


def table_grid(table: IndentTable, depth: float, push_u: float, push_v: float, u: np.ndarray, v: np.ndarray,
               half_span: float) -> np.ndarray:
    """The table's shape on the tensor grid u (nu,) × v (nv,) m → (nu, nv) m for the measured clamp half span
    ``half_span`` m: :meth:`flexsheet.model.sheet_table.IndentTable.evaluate_grid` (equal to the point-wise
    :meth:`~flexsheet.model.sheet_table.IndentTable.evaluate` to rounding, ``tests/unit/model/test_sheet_model.py``).
    The fit's per-frame cost is this."""
    return table.evaluate_grid(depth, push_u, push_v, u, v, half_span)


def contact_of(sheet: SheetSurface, point) -> tuple[float, float, float]:
    """(depth S, push_u, push_v) m of a fingertip ``point`` (3,) m on the flat ``sheet``: S = distance behind the
    sheet plane along −normal, (push_u, push_v) its position in the sheet frame. Raises ``ValueError`` for a
    non-finite point."""
    p = np.asarray(point, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"fingertip must be a finite (3,) point in m, got {point!r}")
    d = p - sheet.origin
    return -float(d @ sheet.normal), float(d @ sheet.axis_u), float(d @ sheet.axis_v)


@dataclass(frozen=True)
class PendingPush:
    """A push whose shape is not known yet (the nominal table of its stretch ``node`` is still being built):
    only the contact and depth (m), enough for the 4-triangle model (``SheetSurface.pushed_point``). It has no
    deflection: :func:`flexsheet.rendering.state.pick_model` never picks ``fine`` for it."""

    half_span: float
    half_width: float
    push_u: float
    push_v: float
    depth: float
    node: float


@dataclass(frozen=True)
class FourTriangleDent(DeflectionGrid):
    """The renderer's 4-triangle pushed sheet (paper §III-C-3: triangles (pushed point, corner i, corner i+1)),
    as a deflection for drawing: w(u, v) = depth · min((a − u)/(a − u0), (u + a)/(u0 + a), (b − v)/(b − v0),
    (v + b)/(v0 + b)) m along −normal (the tent over the sheet's rectangle with its apex at the contact
    (u0, v0) = (``push_u``, ``push_v``)). The viz draws it for a :class:`PendingPush` (the nominal table of
    that stretch is not built yet), which the renderer corrects with ``four_triangle``."""

    half_span: float
    half_width: float
    push_u: float
    push_v: float
    depth: float

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m; ``u``, ``v`` broadcastable (m, sheet frame, clamped onto the sheet)."""
        a, b = self.half_span, self.half_width
        u = np.clip(np.asarray(u, dtype=float), -a, a)
        v = np.clip(np.asarray(v, dtype=float), -b, b)
        tiny = 1e-12                        # a contact on a free edge (|v0| = b) leaves that side vertical
        lam = np.minimum(np.minimum((a - u) / max(a - self.push_u, tiny), (u + a) / max(self.push_u + a, tiny)),
                         np.minimum((b - v) / max(b - self.push_v, tiny), (v + b) / max(self.push_v + b, tiny)))
        return self.depth * np.clip(lam, 0.0, 1.0)



def believed_sheet(T_left: np.ndarray, T_right: np.ndarray, fingertip, model: NominalSheetModel,
                   config: SheetConfig, build: bool = True) -> SheetSurface:
    """The sheet the display believes, shared by the renderer and the viz: flat between the measured clamps
    ``T_left``/``T_right`` (T_display_clamp (4, 4), m) and, when ``fingertip`` (3,) m (None: no valid fix) is
    more than ``config.push_threshold`` behind it, pushed in by ``model`` (:meth:`NominalSheetModel.pushed`;
    a :class:`PendingPush` while that stretch's table is missing and ``build`` is False). Raises
    ``ValueError`` for clamps that give no sheet."""
    flat = SheetSurface.from_clamps(T_left, T_right, half_width=config.half_width)
    if fingertip is None:
        return flat
    return model.pushed(flat, fingertip, config.push_threshold, build=build)


def drawable(sheet: SheetSurface) -> SheetSurface:
    """``sheet`` with a :class:`PendingPush` replaced by its :class:`FourTriangleDent` (what the renderer
    corrects with meanwhile), so that it can be drawn; any other sheet unchanged."""
    m = sheet.membrane
    if isinstance(m, PendingPush):
        return replace(sheet, membrane=FourTriangleDent(m.half_span, m.half_width, m.push_u, m.push_v, m.depth))
    return sheet


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
    # einsum, not BLAS (@): these small products are what a frame costs, and a threaded BLAS on busy cores
    # makes them 10-20x slower (flexsheet bench render, sheet_update)
    F = np.einsum("ku,uv->kv", Phi * wts, W) / a                 # sine coefficients per v, (max_k, nv)
    keep = np.sort(np.argsort(-(F ** 2).sum(axis=1))[:n_modes])
    mus = lam_all[keep][:, None] * np.asarray(mu_scales, float)[None, :]          # (n_modes, J)
    B = green(v, mus.ravel(), push_v, b).reshape(nv, len(keep), J).transpose(1, 0, 2)   # (n_modes, nv, J)
    c = (np.linalg.pinv(B) @ F[keep][:, :, None])[:, :, 0]                          # least squares, (n_modes, J)
    prof = np.einsum("mvj,mj->mv", B, c)                                             # fitted profiles (n_modes, nv)
    R = np.einsum("mu,mv->uv", Phi[keep], prof)
    lam, mu, coef = np.repeat(lam_all[keep], J), mus.ravel(), c.ravel()
    rms = float(np.sqrt(np.mean((R - W) ** 2)))
    return SeriesShape(float(a), float(b), float(push_u), float(push_v), float(depth), lam, mu, coef, source, rms)


class NominalSheetModel:
    """The pushed sheet as the renderer models it: nominal FEM tables per stretch node, fitted into the shader's
    series (module doc). ``material``: nominal sheet (:class:`SheetMaterial`); ``tension_ratio``: assumed
    T_v/T_u; ``prestrain``: assumed pre-strain (0); ``stretch_step``: spacing of the table nodes; ``depths``,
    ``positions`` (m) and ``mesh``: the tables (:class:`IndentTable`); ``cache_dir``: where they are cached
    (default :func:`flexsheet.model.sheet_table.default_cache_dir`); ``n_modes``, ``mu_scales``: the fit;
    ``grid``: (nu, nv) samples of the fit. Table builds log their progress. Raises ``ValueError`` on a bad
    setting."""

    def __init__(self, material: SheetMaterial | None = None, *, tension_ratio: float = 1.0, prestrain: float = 0.0,
                 stretch_step: float = 0.01, depths=MODEL_DEPTHS, positions=TABLE_POSITIONS, mesh: dict | None = None,
                 cache_dir: str | None = None, n_modes: int = 16, mu_scales=(0.4, 0.7, 1.0, 1.6),
                 grid: tuple[int, int] = (193, 121), cache_size: int = 256) -> None:
        self.settings = {"material": material, "tension_ratio": tension_ratio, "prestrain": prestrain,
                         "stretch_step": stretch_step, "depths": tuple(depths), "positions": tuple(positions),
                         "mesh": dict(mesh or {}), "cache_dir": cache_dir, "n_modes": n_modes,
                         "mu_scales": tuple(mu_scales), "grid": tuple(grid), "cache_size": cache_size}
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
        self.settings["cache_dir"] = self.cache_dir
        self.n_modes, self.mu_scales, self.grid_n = int(n_modes), tuple(float(s) for s in mu_scales), tuple(grid)
        self._tables: dict[float, IndentTable] = {}
        #: stretch node → node whose table stands in for it (set where a node's FEM fails to converge)
        self.substitute: dict[float, float] = {}
        self._fits: OrderedDict = OrderedDict()
        self._cache_size = int(cache_size)

    @classmethod
    def nominal(cls, stretch: float | None = None, **kw) -> NominalSheetModel:
        """The default model; with ``stretch``, its table at that node is built (or loaded) now."""
        m = cls(**kw)
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
        """The nominal table at ``node`` (shipped, or built once and cached on disk; a build takes ~30 s on one
        core)."""
        if node not in self._tables:
            ph = self.physics(node)
            if ph.tension_u <= 0.0:
                raise ValueError(f"no tension at stretch {node!r}: the nominal model needs a stretched sheet")
            self._tables[node] = IndentTable(ph, self.depths, self.positions, mesh=self.mesh,
                                             cache_dir=self._folder_of(node))
        return self._tables[node]

    def _folder_of(self, node: float) -> str:
        """Where the table at ``node`` is: the shipped folder (:data:`SHIPPED_TABLES`, the default settings'
        tables at the stretches the arms can hold, so no display builds them at run time) or the cache."""
        key = IndentTable.key_of(self.physics(node), self.depths, self.positions, self.mesh)
        shipped = os.path.join(SHIPPED_TABLES, f"indent_{key}.npz")
        return SHIPPED_TABLES if os.path.isfile(shipped) else self.cache_dir

    def nearest_on_disk(self, node: float, nodes=None) -> float | None:
        """The node nearest ``node`` (itself included) among ``nodes`` (default: every step up to 0.30) whose
        table is on disk, or None."""
        st = self.stretch_step
        cand = nodes if nodes is not None else [round(k * st, 6) for k in range(1, int(round(0.30 / st)) + 1)]
        have = [n for n in cand if self.on_disk(n)]
        return min(have, key=lambda n: (abs(n - node), n)) if have else None

    def on_disk(self, node: float) -> bool:
        """Whether the table at ``node`` is loaded or cached on disk (a file check; loads nothing, builds nothing)."""
        if node in self._tables:
            return True
        key = IndentTable.key_of(self.physics(node), self.depths, self.positions, self.mesh)
        return os.path.isfile(os.path.join(self._folder_of(node), f"indent_{key}.npz"))

    def available(self, node: float) -> bool:
        """Whether the table at ``node`` is loaded, or on disk (then it is loaded now, ~10 ms); never builds."""
        if node not in self._tables:
            tab = IndentTable.cached(self.physics(node), self.depths, self.positions, mesh=self.mesh,
                                     cache_dir=self._folder_of(node))
            if tab is None:
                return False
            self._tables[node] = tab
        return True

    def node_of_span(self, half_span: float) -> float:
        """The table node of a measured clamp half span (m)."""
        return self.node_of(stretch_of_span(half_span, self.material.size))

    def shape(self, half_span: float, depth: float, push_u: float, push_v: float,
              half_width: float = geometry.SHEET_SIZE / 2, build: bool = True) -> SeriesShape | None:
        """The fitted pushed shape for the measured clamp half span (m), depth (m, > 0) and contact (m); with
        ``build`` False, None when the table of its node is not built yet (:meth:`available`). Per call on a
        cache miss: the table on the fit's grid (:func:`table_grid`) and the fit (``flexsheet bench render
        --sheet``)."""
        if not (math.isfinite(depth) and depth > 0.0):
            raise ValueError(f"depth must be finite and > 0, got {depth!r}")
        node = self.substitute.get(self.node_of_span(half_span), self.node_of_span(half_span))
        key = (node, round(half_span, 5), round(depth, 4), round(push_u, 4), round(push_v, 4), round(half_width, 5))
        hit = self._fits.get(key)
        if hit is not None:
            self._fits.move_to_end(key)
            return hit
        if not build and not self.available(node):
            return None
        tab = self.table(node)
        nu, nv = self.grid_n
        u = np.linspace(-half_span, half_span, nu)
        v = np.linspace(-half_width, half_width, nv)
        W = table_grid(tab, depth, push_u, push_v, u, v, half_span)
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

    def pushed(self, flat: SheetSurface, finger, threshold: float = 0.0, build: bool = True) -> SheetSurface:
        """The sheet ``flat`` (from the clamps) pushed by the fingertip ``finger`` (3,) m, or ``flat`` itself when
        the finger is no more than ``threshold`` m behind it or off the sheet. Its membrane is this model's
        shape, or, with ``build`` False and the table of its stretch node not built yet, a :class:`PendingPush`.
        Raises ``ValueError`` for a non-finite finger."""
        depth, pu, pv = contact_of(flat, finger)
        a, b = flat.half_span, flat.half_width
        if depth <= threshold or abs(pu) >= a or abs(pv) > b:
            return flat
        shp = self.shape(a, depth, pu, pv, b, build=build)
        if shp is None:
            shp = PendingPush(a, b, pu, pv, depth, self.node_of_span(a))
        return replace(flat, membrane=shp)

    def describe(self) -> dict:
        """JSON-able description (for reports)."""
        return {"name": "fem_nominal", "young_Pa": self.material.young, "prestrain": self.prestrain,
                "tension_ratio": self.tension_ratio, "stretch_step": self.stretch_step, "depths_m": list(self.depths),
                "positions_m": list(self.positions), "mesh": self.mesh, "n_modes": self.n_modes,
                "mu_scales": list(self.mu_scales), "terms": self.n_modes * len(self.mu_scales),
                "note": "nominal material and assumed tension ratio; never the truth's"}


@dataclass(frozen=True)
class SheetConfig:
    """How the display turns clamp poses and the fingertip into the sheet it believes in (the renderer corrects
    for it, the Foxglove bridge draws it).

    ``half_width`` m: half the free-edge length; ``push_threshold`` m: depth behind the flat sheet that counts
    as a push; the pushed sheet's model (:func:`sheet_model_for`): ``fine_modes`` clamped sine modes (each
    with 4 Green's-function terms, ≤ 16: the shader takes 64 terms), ``tension_ratio`` the ASSUMED T_v/T_u,
    ``cache_dir`` where its FEM tables are cached (None: :func:`flexsheet.model.sheet_table.default_cache_dir`),
    ``mesh`` the FEM mesh options (:class:`flexsheet.model.sheet_fem.SheetFEM` kwargs; {}: the default
    4 mm mesh)."""

    half_width: float = geometry.SHEET_SIZE / 2
    push_threshold: float = 0.001
    fine_modes: int = 16
    tension_ratio: float = 1.0
    cache_dir: str | None = None
    mesh: dict = field(default_factory=dict)


def sheet_model_for(config: SheetConfig = SheetConfig()) -> NominalSheetModel:
    """The display's pushed-sheet model for ``config``: the nominal FEM (the sheet's nominal E and size, no
    pre-strain, the assumed tension ratio) fitted into the fine shader's series; never the truth's values.
    The one constructor the renderer node, the Foxglove bridge, the experiments and the tests use. Raises
    ``ValueError`` on a bad setting."""
    return NominalSheetModel(tension_ratio=config.tension_ratio, n_modes=config.fine_modes,
                             cache_dir=config.cache_dir, mesh=dict(config.mesh))


def ship_tables(nodes=tuple(round(0.01 * k, 6) for k in range(1, 12))) -> list[str]:
    """Build (or take from the cache) the default model's tables at ``nodes`` (the bridges' span band, clamp
    strain 0.01-0.10, and one step past it) and copy them into
    :data:`SHIPPED_TABLES`; returns the files written. Minutes cold (~40 s of one core per table)."""
    import shutil

    m = NominalSheetModel()
    os.makedirs(SHIPPED_TABLES, exist_ok=True)
    out = []
    for node in nodes:
        log.info(f"sheet table at stretch {node:g}")
        m.table(float(node))
        key = IndentTable.key_of(m.physics(node), m.depths, m.positions, m.mesh)
        src = os.path.join(m._folder_of(node), f"indent_{key}.npz")
        dst = os.path.join(SHIPPED_TABLES, os.path.basename(src))
        if os.path.abspath(src) != os.path.abspath(dst):
            shutil.copyfile(src, dst)
        record(dst, "python -m flexsheet.model.sheet_model --ship")
        out.append(dst)
    return out


if __name__ == "__main__":      # pragma: no cover - a maintenance command
    import sys

    if sys.argv[1:] != ["--ship"]:
        sys.exit("usage: python -m flexsheet.model.sheet_model --ship   (rebuild the shipped sheet tables)")
    for f in ship_tables():
        print(f)
