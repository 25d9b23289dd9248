"""The display's pushed-sheet model: the geometrically nonlinear membrane FEM of the sheet gripped on its
clamp edges, with the nominal material and the strain offset identified from pushes, sampled into a depth
table that the renderer's "fine" shader reads from a texture (pure: numpy; the FEM from
:mod:`flexsheet.model.sheet_fem`).

This is the display's only pushed-sheet shape: the renderer corrects its image for it (``RendererState``
attaches it to every push, :meth:`NominalSheetModel.pushed`) and the Foxglove bridge draws it as the sheet the
display believes in (:meth:`flexsheet.viz.scene_builder.SceneBuilder.believed_sheet`); both build it with
:func:`sheet_model_for` from the same :class:`SheetConfig`. It is the sheet the planner presses against: the
planner's force model (:mod:`flexsheet.model.tension`) and this shape take the same identified strain offset
ε₀ from ``display.yaml``'s ``sheet`` entry (``flexsheet calibrate sheet``), and both describe a sheet gripped
on two edges and free on the others (T_v/T_u ≈ 0.035 at its centre: :mod:`flexsheet.model.sheet_prestress`).

1. **Tables** (:meth:`NominalSheetModel.table`): :class:`flexsheet.model.sheet_table.IndentTable` of
   :class:`flexsheet.model.sheet_fem.SheetPhysics` with what the display knows — the sheet's NOMINAL size, E
   and thickness (the shape does not depend on E or t: the pre-tension and the push's stiffness scale
   together), the gripped pre-stress, and the tension of the sheet's own strain, clamp strain + ε₀, on nodes
   every ``stretch_step``. Never the twin's truth (:mod:`flexsheet.twin.truth`: its E, thickness, pre-strain
   and grip slip are drawn, and only the presses' fit ε₀ reaches the display). Solved once per node (~2 min of
   one core for the 9 contact positions) and cached on disk; the default model's tables ship
(:data:`SHIPPED_TABLES`). 2. **Depth table** (:meth:`NominalSheetModel.shape`): per push (measured clamp span,
depth, contact) the tables of the two strain nodes around clamp strain + ε₀ are evaluated on a uniform grid
over the sheet every ``grid_step`` (:func:`table_grid`) and blended linearly in strain: a
:class:`SampledShape`, read between samples by bilinear interpolation in numpy and, from a texture, in the
shader (``shaders/correct.vert``). Cached (LRU) on the contact rounded to 0.1 mm. 3. **In the nodes**:
:meth:`NominalSheetModel.shape` with ``build=False`` never builds a missing table in the caller's thread (a
:class:`PendingPush` instead); the renderer node builds it in a worker process
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
from flexsheet.model.checks import check_positive
from flexsheet.model.sheet import DeflectionGrid, SheetSurface, clamp_half_span, stretch_of_span
from flexsheet.model.sheet_fem import SheetPhysics
from flexsheet.model.sheet_table import TABLE_POSITIONS, IndentTable, default_cache_dir
from flexsheet.model.tension import SheetMaterial, tension

log = logging.getLogger(__name__)

#: the default model's tables at sheet strains 0.01–0.11 (the bridges' span band and one step past it),
#: shipped so that no display builds them while it runs (a table build beside the running graph slowed the
#: loop: flexsheet/runtime/background.py). Regenerate: ``python -m flexsheet.model.sheet_model --ship``.
SHIPPED_TABLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sheet_tables")

__all__ = ["SampledShape", "GRID_STEP", "grid_size", "PendingPush", "FourTriangleDent", "believed_sheet",
           "drawable", "NominalSheetModel",
           "MODEL_DEPTHS", "table_grid", "contact_of", "SheetConfig", "sheet_model_for",
           "ship_tables", "SHIPPED_TABLES"]

#: depths (m) of the tables (the depth table interpolates between them)
MODEL_DEPTHS = (0.005, 0.010, 0.020, 0.030, 0.040, 0.050, 0.060)
#: the depth table's sample spacing, m (docs/renderer.md: the image error against the table itself)
GRID_STEP = 0.002


def _bilinear(W: np.ndarray, a: float, b: float, u, v):
    """(w, ∂w/∂u, ∂w/∂v) of the bilinear interpolant of ``W`` (nu, nv) on the uniform grid over u ∈ [−a, a] ×
    v ∈ [−b, b] at (u, v) (broadcast; clamped onto the sheet). The derivatives are the interpolant's own,
    within the cell the point falls in. The GLSL ``membrane()`` of ``shaders/correct.vert`` computes the
    same."""
    nu, nv = W.shape
    du, dv = 2.0 * a / (nu - 1), 2.0 * b / (nv - 1)
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    x = (np.clip(u, -a, a) + a) / du
    y = (np.clip(v, -b, b) + b) / dv
    i = np.clip(np.floor(x), 0, nu - 2).astype(np.intp)
    j = np.clip(np.floor(y), 0, nv - 2).astype(np.intp)
    tx, ty = x - i, y - j
    w00, w10, w01, w11 = W[i, j], W[i + 1, j], W[i, j + 1], W[i + 1, j + 1]
    w = (1.0 - ty) * ((1.0 - tx) * w00 + tx * w10) + ty * ((1.0 - tx) * w01 + tx * w11)
    wu = ((1.0 - ty) * (w10 - w00) + ty * (w11 - w01)) / du
    wv = ((1.0 - tx) * (w01 - w00) + tx * (w11 - w10)) / dv
    return w, wu, wv


def grid_size(half_span: float, half_width: float, step: float = GRID_STEP) -> tuple[int, int]:
    """(nu, nv): samples of a depth table over the sheet 2a × 2b (``half_span`` a, ``half_width`` b, m) spaced
    no more than ``step`` m. Raises ``ValueError`` for a non-positive size or step."""
    half_span, half_width, step = (check_positive(k, x) for k, x in
                                   (("half_span", half_span), ("half_width", half_width), ("step", step)))
    return (int(math.ceil(2.0 * half_span / step - 1e-9)) + 1,
            int(math.ceil(2.0 * half_width / step - 1e-9)) + 1)


@dataclass(frozen=True)
class SampledShape(DeflectionGrid):
    """A pushed-sheet deflection as the renderer draws it: a depth table ``w`` (nu, nv) float32, m along
    −normal, sampled at u_i = −a + i·2a/(nu − 1), v_j = −b + j·2b/(nv − 1) (``half_span`` a, ``half_width`` b,
    m), read between samples by bilinear interpolation (:meth:`deflection_grad`; the fine shader samples the
    same table from a texture). ``push_u``, ``push_v``, ``depth`` m: the contact it was sampled for;
    ``source``: one line saying what was sampled. The interface of :class:`flexsheet.model.sheet.Membrane`, so
    a :class:`SheetSurface` can carry it. Raises ``ValueError`` naming ``w`` for a table that is not 2-D,
    smaller than 2×2 or not finite."""

    half_span: float
    half_width: float
    push_u: float
    push_v: float
    depth: float
    w: np.ndarray = field(repr=False)
    source: str = ""

    def __post_init__(self) -> None:
        W = np.asarray(self.w, dtype=np.float32)
        if W.ndim != 2 or min(W.shape) < 2 or not np.all(np.isfinite(W)):
            raise ValueError(f"w must be a finite (nu, nv) table with nu, nv >= 2, got shape {W.shape}")
        object.__setattr__(self, "w", W)

    @classmethod
    def of(cls, shape, n_u: int, n_v: int, source: str = "") -> SampledShape:
        """Any pushed-sheet ``shape`` (``half_span``, ``half_width``, ``push_u``, ``push_v``, ``depth``,
        ``deflection``) sampled on an ``n_u`` × ``n_v`` grid. Raises ``ValueError`` for n < 2."""
        if n_u < 2 or n_v < 2:
            raise ValueError(f"n_u and n_v must be >= 2, got {n_u} x {n_v}")
        a, b = shape.half_span, shape.half_width
        u, v = np.linspace(-a, a, n_u), np.linspace(-b, b, n_v)
        return cls(float(a), float(b), float(shape.push_u), float(shape.push_v), float(shape.depth),
                   shape.deflection(u[:, None], v[None, :]), source or type(shape).__name__)

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m; ``u``, ``v`` broadcastable (m, sheet frame, clamped onto the sheet)."""
        return self.deflection_grad(u, v)[0]

    def deflection_grad(self, u, v):
        """(w, ∂w/∂u, ∂w/∂v) at (u, v), broadcast shape of the inputs (bilinear, as the shader)."""
        return _bilinear(self.w.astype(np.float64), self.half_span, self.half_width, u, v)


def table_grid(table: IndentTable, depth: float, push_u: float, push_v: float, u: np.ndarray, v: np.ndarray,
               half_span: float) -> np.ndarray:
    """The table's shape on the tensor grid u (nu,) × v (nv,) m → (nu, nv) m for the measured clamp half span
    ``half_span`` m: :meth:`flexsheet.model.sheet_table.IndentTable.evaluate_grid` (equal to the point-wise
    :meth:`~flexsheet.model.sheet_table.IndentTable.evaluate` to rounding,
    ``tests/unit/model/test_sheet_model.py``). The depth table's per-push cost is this."""
    return table.evaluate_grid(depth, push_u, push_v, u, v, half_span)


def contact_of(sheet: SheetSurface, point) -> tuple[float, float, float]:
    """(depth S, push_u, push_v) m of a fingertip ``point`` (3,) m on the flat ``sheet``: S = distance behind
    the sheet plane along −normal, (push_u, push_v) its position in the sheet frame. Raises ``ValueError`` for
    a non-finite point."""
    p = np.asarray(point, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"fingertip must be a finite (3,) point in m, got {point!r}")
    d = p - sheet.origin
    return -float(d @ sheet.normal), float(d @ sheet.axis_u), float(d @ sheet.axis_v)


@dataclass(frozen=True)
class PendingPush:
    """A push whose shape is not known yet (the table of its strain ``node`` is still being built):
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
    """The renderer's 4-triangle pushed sheet (paper §III-C-3: triangles (pushed point, corner i, corner
    i+1)), as a deflection for drawing: w(u, v) = depth · min((a − u)/(a − u0), (u + a)/(u0 + a), (b − v)/(b −
    v0), (v + b)/(v0 + b)) m along −normal (the tent over the sheet's rectangle with its apex at the contact
    (u0, v0) = (``push_u``, ``push_v``)). The viz draws it for a :class:`PendingPush` (the table of that
    strain is not built yet), which the renderer corrects with ``four_triangle``."""

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
        lam = np.minimum(np.minimum((a - u) / max(a - self.push_u, tiny),
                                    (u + a) / max(self.push_u + a, tiny)),
                         np.minimum((b - v) / max(b - self.push_v, tiny),
                                    (v + b) / max(self.push_v + b, tiny)))
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
        return replace(sheet,
                       membrane=FourTriangleDent(m.half_span, m.half_width, m.push_u, m.push_v, m.depth))
    return sheet


class NominalSheetModel:
    """The pushed sheet as the renderer models it: FEM tables of the sheet gripped on its clamp edges per
    sheet strain node, sampled into depth tables (module doc). ``material``: nominal sheet
    (:class:`SheetMaterial`); ``strain_offset``: the identified ε₀ of ``display.yaml``'s ``sheet`` entry (the
    sheet's strain is the clamp strain + ε₀; 0 without one); ``tension_ratio``: None for the gripped
    pre-stress (default), or an ASSUMED uniform T_v/T_u (a comparison, not the display's model);
    ``stretch_step``: spacing of the table nodes; ``depths``, ``positions`` (m) and ``mesh``: the tables
    (:class:`IndentTable`); ``cache_dir``: where they are cached (default
    :func:`flexsheet.model.sheet_table.default_cache_dir`); ``grid_step`` m: the depth table's sample spacing
    (:class:`SampledShape`, :data:`GRID_STEP`). Table builds log their progress. Raises ``ValueError`` naming
    the setting and value on a bad one."""

    def __init__(self, material: SheetMaterial | None = None, *, strain_offset: float = 0.0,
                 tension_ratio: float | None = None, stretch_step: float = 0.01, depths=MODEL_DEPTHS,
                 positions=TABLE_POSITIONS, mesh: dict | None = None, cache_dir: str | None = None,
                 grid_step: float = GRID_STEP, cache_size: int = 256) -> None:
        self.settings = {"material": material, "strain_offset": strain_offset, "tension_ratio": tension_ratio,
                         "stretch_step": stretch_step, "depths": tuple(depths), "positions": tuple(positions),
                         "mesh": dict(mesh or {}), "cache_dir": cache_dir, "grid_step": grid_step,
                         "cache_size": cache_size}
        self.material = material or SheetMaterial()
        for k, v in (("tension_ratio", 1.0 if tension_ratio is None else tension_ratio),
                     ("stretch_step", stretch_step), ("grid_step", grid_step)):
            check_positive(k, v)
        if not (math.isfinite(strain_offset) and abs(strain_offset) < 0.1):
            raise ValueError(f"strain_offset must be finite and within ±0.1, got {strain_offset!r}")
        self.tension_ratio = None if tension_ratio is None else float(tension_ratio)
        self.strain_offset, self.stretch_step = float(strain_offset), float(stretch_step)
        self.depths, self.positions = tuple(depths), tuple(positions)
        self.mesh = dict(mesh or {})
        self.cache_dir = cache_dir or default_cache_dir()
        self.settings["cache_dir"] = self.cache_dir
        self.grid_step = float(grid_step)
        self._tables: dict[float, IndentTable] = {}
        #: strain node → node whose table stands in for it (set where a node's FEM fails to converge)
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
        """The table node nearest the sheet's strain at clamp strain ``stretch`` (``stretch`` +
        ``strain_offset``), at least one step (the planner never leaves the sheet slack:
        ``SheetMaterial.min_stretch`` = 0.01; an unstretched membrane has no pre-tension)."""
        st = self.stretch_step
        return round(max(st, round((float(stretch) + self.strain_offset) / st) * st), 6)

    def physics(self, node: float) -> SheetPhysics:
        """The physics of the table at sheet strain ``node``: E, thickness and size of ``material`` (the shape
        does not depend on E or t: T and the stiffness of the push scale together), clamp half span and
        T_u = tension at that strain, the gripped pre-stress (or the assumed ``tension_ratio``)."""
        size = self.material.size
        return SheetPhysics(half_span=clamp_half_span(node, size), half_width=size / 2,
                            young=self.material.young,
                            thickness=self.material.thickness, tension_u=tension(node, self.material),
                            tension_ratio=self.tension_ratio)

    def table(self, node: float) -> IndentTable:
        """The table at strain node ``node`` (shipped, or built once and cached on disk; a build takes ~2 min
        of one core)."""
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
        """Whether the table at ``node`` is loaded or cached on disk (a file check; loads nothing, builds
        nothing)."""
        if node in self._tables:
            return True
        key = IndentTable.key_of(self.physics(node), self.depths, self.positions, self.mesh)
        return os.path.isfile(os.path.join(self._folder_of(node), f"indent_{key}.npz"))

    def available(self, node: float) -> bool:
        """Whether the table at ``node`` is loaded, or on disk (then it is loaded now, ~10 ms); never
        builds."""
        if node not in self._tables:
            tab = IndentTable.cached(self.physics(node), self.depths, self.positions, mesh=self.mesh,
                                     cache_dir=self._folder_of(node))
            if tab is None:
                return False
            self._tables[node] = tab
        return True

    def node_of_span(self, half_span: float) -> float:
        """The table node of a measured clamp half span (m): :meth:`node_of` its clamp strain."""
        return self.node_of(stretch_of_span(half_span, self.material.size))

    def grid_of(self, half_span: float, half_width: float) -> tuple[int, int]:
        """(nu, nv): samples of the depth table over the sheet 2a × 2b (m), :func:`grid_size` at
        ``grid_step``."""
        return grid_size(half_span, half_width, self.grid_step)

    def shape(self, half_span: float, depth: float, push_u: float, push_v: float,
              half_width: float = geometry.SHEET_SIZE / 2, build: bool = True) -> SampledShape | None:
        """The pushed shape for the measured clamp half span (m), depth (m, > 0) and contact (m) as a depth
        table (:class:`SampledShape`, :meth:`grid_of` samples of the FEM table, :func:`table_grid`); with
        ``build`` False, None when the table of its node is not built yet (:meth:`available`). Cached (LRU) on
        the contact rounded to 0.1 mm. Raises ``ValueError`` for a depth that is not > 0."""
        if not (math.isfinite(depth) and depth > 0.0):
            raise ValueError(f"depth must be finite and > 0, got {depth!r}")
        strain = stretch_of_span(half_span, self.material.size) + self.strain_offset
        nodes = [(self.substitute.get(n, n), wt) for n, wt in self.blend_of(strain)]
        key = (tuple(nodes), round(half_span, 5), round(depth, 4), round(push_u, 4), round(push_v, 4),
               round(half_width, 5))
        hit = self._fits.get(key)
        if hit is not None:
            self._fits.move_to_end(key)
            return hit
        if not build and not all(self.available(n) for n, _ in nodes):
            return None
        nu, nv = self.grid_of(half_span, half_width)
        u = np.linspace(-half_span, half_span, nu)
        v = np.linspace(-half_width, half_width, nv)
        W = sum(wt * table_grid(self.table(n), depth, push_u, push_v, u, v, half_span) for n, wt in nodes)
        pre = "gripped" if self.tension_ratio is None else f"ASSUMED uniform T_v/T_u {self.tension_ratio:g}"
        src = (f"sheet FEM ({pre}, sheet strain {strain:.4f} = clamp strain + identified offset "
               f"{self.strain_offset:+.4f}; nodes {' + '.join(f'{wt:.2f}x{n:g}' for n, wt in nodes)}), "
               f"depth table {nu}x{nv}")
        out = SampledShape(half_span, half_width, push_u, push_v, depth, W, src)
        self._fits[key] = out
        if len(self._fits) > self._cache_size:
            self._fits.popitem(last=False)
        return out

    def blend_of(self, strain: float) -> list[tuple[float, float]]:
        """[(node, weight), ...]: the table nodes whose shapes, blended linearly, give the sheet at ``strain``
        (the sheet's own strain, clamp strain + ``strain_offset``): the two around it, or one where the
        other's weight is below 1 % (a shape change of ≲ 2 µm; at least one step, as :meth:`node_of`)."""
        st = self.stretch_step
        x = max(float(strain), st) / st
        lo = math.floor(x + 1e-9)
        t = x - lo
        pairs = [(round(lo * st, 6), 1.0 - t), (round((lo + 1) * st, 6), t)]
        keep = [(n, wt) for n, wt in pairs if wt >= 0.01]
        total = sum(wt for _, wt in keep)
        return [(n, wt / total) for n, wt in keep]

    def missing(self, half_span: float) -> float | None:
        """The first table node the shape at the measured clamp half span (m) needs that is not on disk (None:
        all are): what the renderer node builds next."""
        strain = stretch_of_span(half_span, self.material.size) + self.strain_offset
        for n, _ in self.blend_of(strain):
            n = self.substitute.get(n, n)
            if not self.available(n):
                return n
        return None

    def surface(self, sheet: SheetSurface) -> SheetSurface:
        """``sheet`` with its membrane (the measured depth and contact) replaced by this model's shape; a flat
        sheet is returned as is."""
        m = sheet.membrane
        if m is None or m.depth <= 0.0:
            return sheet
        return replace(sheet,
                       membrane=self.shape(sheet.half_span, m.depth, m.push_u, m.push_v, sheet.half_width))

    def pushed(self, flat: SheetSurface, finger, threshold: float = 0.0, build: bool = True) -> SheetSurface:
        """The sheet ``flat`` (from the clamps) pushed by the fingertip ``finger`` (3,) m, or ``flat`` itself
        when the finger is no more than ``threshold`` m behind it or off the sheet. Its membrane is this
        model's shape, or, with ``build`` False and a table it needs not built yet, a :class:`PendingPush`.
        Raises ``ValueError`` for a non-finite finger."""
        depth, pu, pv = contact_of(flat, finger)
        a, b = flat.half_span, flat.half_width
        if depth <= threshold or abs(pu) >= a or abs(pv) > b:
            return flat
        shp = self.shape(a, depth, pu, pv, b, build=build)
        if shp is None:
            shp = PendingPush(a, b, pu, pv, depth, self.missing(a) or self.node_of_span(a))
        return replace(flat, membrane=shp)

    def describe(self) -> dict:
        """JSON-able description (for reports)."""
        return {"name": "fem_gripped" if self.tension_ratio is None else "fem_uniform",
                "young_Pa": self.material.young, "strain_offset": self.strain_offset,
                "tension_ratio": self.tension_ratio, "stretch_step": self.stretch_step,
                "depths_m": list(self.depths),
                "positions_m": list(self.positions), "mesh": self.mesh, "grid_step_m": self.grid_step,
                "note": "nominal E and size, the identified strain offset (display.yaml sheet entry); never "
                        "the truth's"}


@dataclass(frozen=True)
class SheetConfig:
    """How the display turns clamp poses and the fingertip into the sheet it believes in (the renderer
    corrects for it, the Foxglove bridge draws it).

    ``half_width`` m: half the free-edge length; ``push_threshold`` m: depth behind the flat sheet that counts
    as a push; the pushed sheet's model (:func:`sheet_model_for`): ``grid_step`` m the depth table's sample
    spacing, ``strain_offset`` the identified ε₀ (``display.yaml``'s ``sheet`` entry; 0 without one),
    ``tension_ratio`` None (the gripped sheet) or an ASSUMED uniform T_v/T_u, ``cache_dir`` where its FEM
    tables are cached (None: :func:`flexsheet.model.sheet_table.default_cache_dir`), ``mesh`` the FEM mesh
    options (:class:`flexsheet.model.sheet_fem.SheetFEM` kwargs; {}: the default 4 mm mesh)."""

    half_width: float = geometry.SHEET_SIZE / 2
    push_threshold: float = 0.001
    grid_step: float = GRID_STEP
    strain_offset: float = 0.0
    tension_ratio: float | None = None
    cache_dir: str | None = None
    mesh: dict = field(default_factory=dict)


def sheet_model_for(config: SheetConfig = SheetConfig()) -> NominalSheetModel:
    """The display's pushed-sheet model for ``config``: the FEM of the sheet gripped on its clamp edges with
    the nominal E and size and the identified strain offset, sampled into depth tables; never the truth's
    values. The one constructor the renderer node, the Foxglove bridge, the experiments and the tests use.
    Raises ``ValueError`` on a bad setting."""
    return NominalSheetModel(strain_offset=config.strain_offset, tension_ratio=config.tension_ratio,
                             grid_step=config.grid_step, cache_dir=config.cache_dir, mesh=dict(config.mesh))


def ship_tables(nodes=tuple(round(0.01 * k, 6) for k in range(1, 12))) -> list[str]:
    """Build (or take from the cache) the default model's tables at ``nodes`` (sheet strains 0.01-0.11: the
    bridges' span band, clamp strain 0.01-0.10, and one step past it) and copy them into
    :data:`SHIPPED_TABLES`; returns the files written. Tens of minutes cold (~2 min of one core per table)."""
    import shutil
    import tempfile

    m = NominalSheetModel()
    os.makedirs(SHIPPED_TABLES, exist_ok=True)
    out = []
    for node in nodes:
        log.info(f"sheet table at strain {node:g}")
        m.table(float(node))
    with tempfile.TemporaryDirectory() as tmp:         # staged: the first entry replaces the earlier models'
        staged = []
        for node in nodes:
            key = IndentTable.key_of(m.physics(node), m.depths, m.positions, m.mesh)
            name = f"indent_{key}.npz"
            shutil.copyfile(os.path.join(m._folder_of(node), name), os.path.join(tmp, name))
            staged.append(name)
        for i, name in enumerate(staged):
            dst = os.path.join(SHIPPED_TABLES, name)
            shutil.copyfile(os.path.join(tmp, name), dst)
            record(dst, "python -m flexsheet.model.sheet_model --ship",
                   replaces="indent_" if i == 0 else None)
            out.append(dst)
    return out


if __name__ == "__main__":      # pragma: no cover - a maintenance command
    import sys

    if sys.argv[1:] != ["--ship"]:
        sys.exit("usage: python -m flexsheet.model.sheet_model --ship   (rebuild the shipped sheet tables)")
    for f in ship_tables():
        print(f)
