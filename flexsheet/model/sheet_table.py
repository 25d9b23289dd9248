"""The true sheet's indentation table (:class:`IndentTable`) of the pushed sheet of
:class:`flexsheet.model.sheet_fem.SheetFEM`.

The world needs the shape at 100 Hz; one solve takes seconds. So the shape is
solved once per physics on a grid of depths × contact positions (|u₀|, |v₀| ≥ 0; the other quadrants by
symmetry), cached on disk, and interpolated (:meth:`IndentTable.shape`): between contact positions by
blending the neighbouring solutions after a piecewise-linear remapping of each axis that moves their contact
to the requested one while keeping the edges fixed (so the peak stays at the finger and the clamped edges
stay at zero), and between depths by blending the two neighbouring depths' solutions, each scaled to the
requested depth. ``tests/unit/model/test_sheet_table.py`` checks the interpolation against direct solves.

Units: m, N; frames: the sheet's (u, v)."""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
from dataclasses import dataclass, field

import numpy as np

from flexsheet.dirs import cache_root
from flexsheet.model.checks import check_positive
from flexsheet.model.sheet import DeflectionGrid
from flexsheet.model.sheet_fem import SheetFEM, SheetPhysics, bilinear

log = logging.getLogger(__name__)

__all__ = ["FemShape", "IndentTable", "bracket_weights", "TABLE_DEPTHS", "TABLE_POSITIONS", "TABLE_VERSION",
           "default_cache_dir"]


#: depths (m) of the table, after 0 (flat)
TABLE_DEPTHS = (0.003, 0.010, 0.020, 0.035, 0.050)


#: contact positions (m) along each of u and v of the table (≥ 0; mirrored); multiples of the default 4 mm
#: mesh so that the fingertip apex sits on a node
TABLE_POSITIONS = (0.0, 0.036, 0.072)


#: formulation version in every table's cache key (:meth:`IndentTable.key_of`): 2 = with the tension-field
#: relaxation (wrinkling); version-1 tables differ by up to 0.67 mm at 60 mm depth off-centre and are rebuilt
TABLE_VERSION = 2


def default_cache_dir() -> str:
    """Folder for cached tables: ``$FLEXSHEET_CACHE/sheet_fem`` or ``~/.cache/flexsheet/sheet_fem``."""
    return os.path.join(cache_root(), "sheet_fem")


# ------------------------------------------------------------------------------------------------ table
def _interp_1d(x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i (n,), t (n,)): 1-D linear interpolation on the increasing axis ``x`` at ``q`` (clamped) is
    (1 − t)·F[i] + t·F[i + 1], the per-axis factor of :func:`bilinear`."""
    qq = np.clip(q, x[0], x[-1])
    i = np.clip(np.searchsorted(x, qq, side="right") - 1, 0, len(x) - 2)
    return i, (qq - x[i]) / (x[i + 1] - x[i])


def _remap(q: np.ndarray, target: float, node: float, L: float) -> np.ndarray:
    """Piecewise-linear map of [−L, L] onto itself sending ``target`` to ``node`` (edges fixed)."""
    target = min(max(target, -L * (1 - 1e-9)), L * (1 - 1e-9))
    lo = -L + (q + L) * (node + L) / (target + L)
    hi = node + (q - target) * (L - node) / (L - target)
    return np.where(q <= target, lo, hi)


#: depth step of the incremental stiffness, m
STIFFNESS_STEP = 0.0005


@dataclass(frozen=True)
class FemShape(DeflectionGrid):
    """The true pushed sheet from an :class:`IndentTable` (the interface of
    :class:`flexsheet.model.sheet.Membrane`: ``half_span``, ``half_width``, ``push_u``, ``push_v``,
    ``depth``, ``tension_ratio``, :meth:`deflection`, :meth:`deflection_grad`, :meth:`grid`), so a
    :class:`flexsheet.model.sheet.SheetSurface` can carry it. ``force``: interpolated contact force, N;
    ``stiffness``: its incremental stiffness dF/d(depth), N/m (central difference of the table's force over
    ±0.5 mm of depth)."""

    table: IndentTable = field(repr=False)
    half_span: float
    half_width: float
    push_u: float
    push_v: float
    depth: float
    force: float = 0.0
    stiffness: float = 0.0

    @property
    def tension_ratio(self) -> float | None:
        """The uniform tension ratio β the table was solved with, or None: the gripped sheet's pre-stress."""
        return self.table.physics.tension_ratio

    def deflection(self, u, v) -> np.ndarray:
        """w(u, v), m along −normal, sheet frame (broadcast; clamped to the sheet)."""
        return self.table.evaluate(self.depth, self.push_u, self.push_v, u, v, self.half_span)

    def deflection_grad(self, u, v, h: float = 2e-4):
        """(w, ∂w/∂u, ∂w/∂v) by central differences with step ``h`` m."""
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        w = self.deflection(u, v)
        wu = (self.deflection(u + h, v) - self.deflection(u - h, v)) / (2 * h)
        wv = (self.deflection(u, v + h) - self.deflection(u, v - h)) / (2 * h)
        return w, wu, wv



def bracket_weights(axis: np.ndarray, q: float) -> list[tuple[int, float]]:
    """(index, weight) pairs of linear interpolation on the increasing ``axis`` (n,) at ``q``, held at its
    ends."""
    if q <= axis[0]:
        return [(0, 1.0)]
    if q >= axis[-1]:
        return [(len(axis) - 1, 1.0)]
    i = int(np.searchsorted(axis, q, side="right") - 1)
    t = (q - axis[i]) / (axis[i + 1] - axis[i])
    return [(i, 1.0 - t), (i + 1, t)]

class IndentTable:
    """Solutions of one :class:`SheetPhysics` over ``depths`` (m, increasing, > 0) × ``positions`` (m, ≥ 0,
    increasing, starting at 0, used for both |u₀| and |v₀|), built with :class:`SheetFEM` (``mesh`` kwargs) or
    loaded from ``cache_dir`` (a file named by a hash of everything that defines it); a build logs its
    progress. Interpolation: module doc. Raises ``ValueError`` on bad axes."""

    def __init__(self, physics: SheetPhysics, depths=TABLE_DEPTHS, positions=TABLE_POSITIONS, *,
                 mesh: dict | None = None, cache_dir: str | None = None) -> None:
        self.physics = physics
        self.depths = np.asarray(depths, float)
        self.positions = np.asarray(positions, float)
        if (self.depths.ndim != 1 or self.depths.size < 1 or np.any(self.depths <= 0)
                or np.any(np.diff(self.depths) <= 0)):
            raise ValueError(f"depths must be increasing and > 0, got {depths!r}")
        if (self.positions.ndim != 1 or self.positions.size < 1 or self.positions[0] != 0.0
                or np.any(np.diff(self.positions) <= 0)):
            raise ValueError(f"positions must start at 0 and increase, got {positions!r}")
        if self.positions[-1] >= min(physics.half_span - physics.finger_radius, physics.half_width):
            raise ValueError(f"positions must stay inside the sheet, got {positions!r}")
        self.mesh = dict(mesh or {})
        self.cache_dir = cache_dir
        self.built_from_cache = False
        self.key = self.key_of(physics, self.depths, self.positions, self.mesh)
        path = os.path.join(cache_dir, f"indent_{self.key}.npz") if cache_dir else None
        if path and os.path.isfile(path):
            try:
                z = np.load(path)
                self.x, self.y, self.W, self.F = z["x"], z["y"], z["W"], z["F"]
                self.built_from_cache = True
                return
            except (OSError, KeyError, ValueError):
                pass
        self._build()
        if path:
            os.makedirs(cache_dir, exist_ok=True)
            tmp = f"{path}.{os.getpid()}.tmp.npz"
            np.savez_compressed(tmp, x=self.x, y=self.y, W=self.W, F=self.F)
            os.replace(tmp, path)

    @classmethod
    def from_arrays(cls, physics: SheetPhysics, depths, positions, x, y, W, F) -> IndentTable:
        """A table of solutions solved elsewhere: node coordinates ``x`` (nx,), ``y`` (ny,) m, deflections
        ``W`` (P, P, S, nx, ny) m and forces ``F`` (P, P, S) N over ``positions`` (P) × ``depths`` (S);
        nothing is built or cached."""
        tab = cls.__new__(cls)
        tab.physics, tab.mesh, tab.cache_dir, tab.built_from_cache = physics, {}, None, True
        tab.depths, tab.positions = np.asarray(depths, float), np.asarray(positions, float)
        tab.x, tab.y, tab.W, tab.F = (np.asarray(x, float), np.asarray(y, float), np.asarray(W),
                                      np.asarray(F, float))
        tab.key = cls.key_of(physics, tab.depths, tab.positions)
        return tab

    @staticmethod
    def key_of(physics: SheetPhysics, depths, positions, mesh: dict | None = None) -> str:
        """The cache key (20 hex digits) of a table: a hash of everything that defines it."""
        doc = {"physics": physics.key(), "depths": np.asarray(depths, float).round(9).tolist(),
               "positions": np.asarray(positions, float).round(9).tolist(), "mesh": dict(mesh or {}),
               "version": TABLE_VERSION}
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:20]

    @classmethod
    def cached(cls, physics: SheetPhysics, depths=TABLE_DEPTHS, positions=TABLE_POSITIONS, *,
               mesh: dict | None = None, cache_dir: str) -> IndentTable | None:
        """The table if ``cache_dir`` holds it, else ``None`` (never builds)."""
        key = cls.key_of(physics, depths, positions, mesh)
        if not cache_dir or not os.path.isfile(os.path.join(cache_dir, f"indent_{key}.npz")):
            return None
        return cls(physics, depths, positions, mesh=mesh, cache_dir=cache_dir)

    def _build(self) -> None:
        fem = SheetFEM(self.physics, **self.mesh)
        P, S = self.positions, self.depths
        self.x, self.y = fem.x, fem.y
        self.W = np.zeros((P.size, P.size, S.size, fem.x.size, fem.y.size))
        self.F = np.zeros((P.size, P.size, S.size))
        n = 0
        for i, pu in enumerate(P):
            for j, pv in enumerate(P):
                sols = fem.solve_indent(list(S), float(pu), float(pv))
                for k, s in enumerate(sols):
                    self.W[i, j, k] = s.w
                    self.F[i, j, k] = s.force
                n += 1
                log.info(f"sheet FEM table {n}/{P.size ** 2} (contact u={pu * 1e3:.0f} mm, v={pv * 1e3:.0f} "
                         "mm)")

    def shape(self, depth: float, push_u: float, push_v: float, half_span: float | None = None) -> FemShape:
        """The interpolated true shape at ``depth`` (m, ≥ 0), contact (push_u, push_v) (m); ``half_span``
        (m): the actual clamp half span (default the table's; a different span is mapped onto the table's by
        scaling u). Raises ``ValueError`` for a contact outside the sheet or a negative depth."""
        a = self.physics.half_span if half_span is None else check_positive("half_span", half_span)
        b = self.physics.half_width
        if not (math.isfinite(depth) and depth >= 0.0):
            raise ValueError(f"depth must be finite and >= 0, got {depth!r}")
        if not (abs(push_u) < a and abs(push_v) <= b):
            raise ValueError(f"pushed point ({push_u!r}, {push_v!r}) lies outside the sheet |u| < {a}, |v| "
                             f"<= {b}")
        pu = abs(push_u) * self.physics.half_span / a
        force = self._force(depth, pu, abs(push_v))
        h = STIFFNESS_STEP
        lo = max(depth - h, 0.0)
        k = (self._force(depth + h, pu, abs(push_v)) - self._force(lo, pu, abs(push_v))) / (depth + h - lo)
        return FemShape(self, a, b, float(push_u), float(push_v), float(depth), force, max(float(k), 0.0))

    def _depth_weights(self, depth: float) -> list[tuple[int, float]]:
        """(index, weight) pairs whose fields, each scaled by depth/S_k, blend to the shape at ``depth``."""
        S = self.depths
        if depth <= S[0]:
            return [(0, depth / S[0])]
        if depth >= S[-1]:
            return [(len(S) - 1, depth / S[-1])]
        return [(k, wt * depth / S[k]) for k, wt in bracket_weights(S, depth)]

    def _force(self, depth: float, pu: float, pv: float) -> float:
        f = 0.0
        for i, wi in bracket_weights(self.positions, pu):
            for j, wj in bracket_weights(self.positions, pv):
                for k, wk in self._depth_weights(depth):
                    f += wi * wj * wk * self.F[i, j, k]
        return float(f)

    def evaluate(self, depth: float, push_u: float, push_v: float, u, v, half_span: float | None = None
                 ) -> np.ndarray:
        """w (m) at sheet points (u, v) (broadcast) for the contact (push_u, push_v) at ``depth`` (module
        doc)."""
        a_t, b = self.physics.half_span, self.physics.half_width
        a = a_t if half_span is None else float(half_span)
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        if depth <= 0.0:
            return np.zeros(u.shape)
        s = a_t / a
        uq = np.clip(u * s * math.copysign(1.0, push_u or 1.0), -a_t, a_t)
        vq = np.clip(v * math.copysign(1.0, push_v or 1.0), -b, b)
        pu, pv = abs(push_u) * s, abs(push_v)
        out = np.zeros(u.shape)
        for i, wi in bracket_weights(self.positions, pu):
            xu = _remap(uq, pu, self.positions[i], a_t)
            for j, wj in bracket_weights(self.positions, pv):
                yv = _remap(vq, pv, self.positions[j], b)
                for k, wk in self._depth_weights(depth):
                    out += (wi * wj * wk) * bilinear(self.x, self.y, self.W[i, j, k], xu, yv)
        return out

    def evaluate_grid(self, depth: float, push_u: float, push_v: float, u, v, half_span: float | None = None
                      ) -> np.ndarray:
        """:meth:`evaluate` on the tensor grid ``u`` (nu,) × ``v`` (nv,) (m, sheet frame: u along the clamp
        line, v across; points off the sheet are clamped onto it) → w (nu, nv), m along −normal, for the
        contact (``push_u``, ``push_v``) m at ``depth`` m (≤ 0: a flat sheet, zeros) and the actual clamp half
        span ``half_span`` m (default the table's). The same interpolation (contact remapping per axis,
        bilinear in the FEM nodes, blend of the neighbouring depths and contacts), done one axis after the
        other: equal to :meth:`evaluate` at (u[:, None], v[None, :]) to rounding (≲ 1e-16 m) and ~20× faster
        on a fit grid (``tests/unit/model/test_sheet_model.py``). Raises ``ValueError`` when ``u`` or ``v`` is
        not 1-D."""
        a_t, b = self.physics.half_span, self.physics.half_width
        u, v = np.asarray(u, float), np.asarray(v, float)
        if u.ndim != 1 or v.ndim != 1:
            raise ValueError(f"u and v must be 1-D, got shapes u {u.shape} and v {v.shape}")
        if depth <= 0.0:
            return np.zeros((u.size, v.size))
        s = a_t / (a_t if half_span is None else float(half_span))
        uq = np.clip(u * s * math.copysign(1.0, push_u or 1.0), -a_t, a_t)
        vq = np.clip(v * math.copysign(1.0, push_v or 1.0), -b, b)
        pu, pv = abs(push_u) * s, abs(push_v)
        out = np.zeros((u.size, v.size))
        kw = self._depth_weights(depth)
        for i, wi in bracket_weights(self.positions, pu):
            iu, tu = _interp_1d(self.x, _remap(uq, pu, self.positions[i], a_t))
            for j, wj in bracket_weights(self.positions, pv):
                iv, tv = _interp_1d(self.y, _remap(vq, pv, self.positions[j], b))
                Wij = sum(wk * self.W[i, j, k] for k, wk in kw)
                Wu = (1.0 - tu)[:, None] * Wij[iu] + tu[:, None] * Wij[iu + 1]            # along u, (nu, ny)
                out += (wi * wj) * ((1.0 - tv)[None, :] * Wu[:, iv] + tv[None, :] * Wu[:, iv + 1])
        return out
