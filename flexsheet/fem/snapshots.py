"""Precomputed nonlinear snapshots interpolated over contact position and depth: the real-time nonlinear
model.

Peterlík, Sedef, Basdogan & Matyska, "Real-time visio-haptic interaction with static soft tissue models having
geometric and material nonlinearity", Computers & Graphics 34(1), 2010: precompute nonlinear solutions over
the finger's state space offline and interpolate them at haptic rate. Here the state is (azimuth φ of the
contact point, push depth d, axial offset a) and the stored quantity is the displacement of the *surface*, the
only thing the renderer draws.

* **Offline** (:func:`flexsheet.fem.reference.snapshot_build.build_table`): for each snapshot azimuth φ_i the
  hyperelastic reference (the material's law: neo-Hookean, or Gent — the paper's cylinder's)
  (:mod:`flexsheet.fem.reference.hyperelastic`) is pushed 0 → d_max with load stepping, and every converged
  depth d_j is sampled on a fixed surface grid: the side surface on (θ, y) and the end cap on (θ, ρ),
  display-frame components. Also stored per (φ_i, d_j): finger force, largest strain, inverted elements, min
  det F.
* **Run time** (:meth:`SnapshotModel.surface`): the cylinder is rotationally symmetric about its axis except
  for the support, so each snapshot is *rotated with the finger*: for a push at φ between φ_i and φ_i+1 the
  field of snapshot i is rotated by δ_i = φ − φ_i about the axis (u(θ) ≈ R(δ_i)·U_i(θ − δ_i)) and the two are
  blended linearly in φ, and linearly in depth between d_j and d_j+1. Rotating first removes the
  "ghosting" a plain blend of two fields centred 10° apart would give; what is left to interpolate is the slow
  change of the support's influence with φ. Negative φ use the z-mirror image, axial offsets a translation
  along y (both exact symmetries of the geometry, except the end caps for a translation: stated, bounded by
  ``axial_max``). Cost: 16 bilinear look-ups per rendered vertex, no solve.

Memory: float32, (#φ × #d × #θ × (#y + #ρ) × 3) × 4 bytes (≈ 30 MB for the default table).

This module is the run-time side (the grid, the table's key and look-up, :func:`load_snapshot_table`); the
build is :mod:`flexsheet.fem.reference.snapshot_build`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.cache import cache_key
from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.versions import UNLOAD_VERSION, solver_tag

__all__ = ["SnapshotGrid", "SnapshotModel", "surface_coords", "TABLE_VERSION", "DEFAULT_GRID",
           "DEFAULT_REF_SPEC",
           "table_key", "load_snapshot_table", "bilinear"]

#: table layout and content; the solver and mesh enter the key through SOLVER_VERSION, spec. snap-2: every
#: azimuth's states are the stable branch (:func:`flexsheet.fem.reference.path_solver.stable_states`), not the
#: loading path
TABLE_VERSION = "snap-2"


@dataclass(frozen=True)
class SnapshotGrid:
    """Sampling of the snapshot table: ``angles_deg`` snapshot azimuths (≥ 0, ascending), ``depth_max`` m,
    ``depth_step`` m (load step and depth sample), ``dtheta_deg`` θ spacing of the surface grid, ``dy`` m
    spacing along y near the push plane (coarser by 2× beyond 20 mm and 40 mm), ``drho`` m radial spacing on
    the cap. Raises ``ValueError`` on bad values."""

    #: every 10° over the stroke (0–60°): a sticking finger carries the material with it, so the field turns
    #: with the azimuth (a frictionless one let it slide by an amount that changed steeply between 5° and 10°,
    #: which took 5°, 7.5° and 55° besides)
    angles_deg: tuple[float, ...] = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0)
    depth_max: float = 0.05
    depth_step: float = 0.0025
    dtheta_deg: float = 0.5
    dy: float = 0.0005
    drho: float = 0.001

    def __post_init__(self):
        a = np.asarray(self.angles_deg, float)
        if a.ndim != 1 or len(a) == 0 or np.any(~np.isfinite(a)) or np.any(np.diff(a) <= 0) or a[0] < 0 \
                or a[-1] > 80:
            raise ValueError(f"angles_deg must be ascending, finite, in [0, 80], got {self.angles_deg!r}")
        if not (math.isfinite(self.depth_max) and 0 < self.depth_max <= 0.07):
            raise ValueError(f"depth_max must be in (0, 0.07] m, got {self.depth_max!r}")
        if not (math.isfinite(self.depth_step) and 0 < self.depth_step <= self.depth_max):
            raise ValueError(f"depth_step must be in (0, depth_max] m, got {self.depth_step!r}")
        for name in ("dtheta_deg", "dy", "drho"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")

    def key(self) -> str:
        """Stable text key (cache keys)."""
        return (f"a={','.join(f'{x:g}' for x in self.angles_deg)},dmax={self.depth_max:g},ds="
                f"{self.depth_step:g},dt={self.dtheta_deg:g},dy={self.dy:g},dr={self.drho:g}")

    def depths(self) -> np.ndarray:
        """Depth samples (m), 0 … depth_max."""
        n = int(round(self.depth_max / self.depth_step))
        return np.linspace(0.0, n * self.depth_step, n + 1)

    def thetas(self) -> np.ndarray:
        """θ samples (rad) over the free half [−90°, 90°] plus a margin of one snapshot spacing."""
        a = np.asarray(self.angles_deg, float)
        margin = float(np.max(np.diff(a))) if len(a) > 1 else 10.0
        lim = 90.0 + margin
        n = int(math.ceil(2 * lim / self.dtheta_deg))
        return np.radians(np.linspace(-lim, lim, n + 1))

    def ys(self, half_length: float) -> np.ndarray:
        """y samples (m, relative to the cylinder centre), 0 … L/2, fine near the push plane."""
        a = np.arange(0.0, min(0.02, half_length), self.dy)
        b = np.arange(a[-1] + 2 * self.dy, min(0.04, half_length), 2 * self.dy) if half_length > 0.02 else []
        last = b[-1] if len(b) else a[-1]
        c = np.arange(last + 4 * self.dy, half_length, 4 * self.dy) if half_length > 0.04 else []
        return np.unique(np.concatenate([a, b, c, [half_length]]))

    def rhos(self, radius: float) -> np.ndarray:
        """Cap radius samples (m), 0 … R."""
        n = int(math.ceil(radius / self.drho))
        return np.linspace(0.0, radius, n + 1)


DEFAULT_GRID = SnapshotGrid()
#: mesh of the snapshot solves, one of the experiment's convergence levels: P2, 12 mm elements, 4.5 mm within
#: 18 mm of the fingertip's whole push path (55 mm deep) (docs/fem.md; a cut half model, ~10 min of one core
#: per azimuth under the sticking finger: ``flexsheet experiment fem --node-table --contact sticking --azimuth
#: A``). Off azimuth 0 the half model is *cut*: its mesh has nodes on the plane through the push axis, as the
#: quarter model has on its mirror plane; without them a half model is 8–12 % stiffer at 40–50 mm than the
#: quarter model of the same h_fine, with them within 1.1 % on the 4.5 and 3.4 mm meshes (3.5 % on the 6 mm
#: one; the experiment's mirror study, docs/fem.md)
DEFAULT_REF_SPEC = RefSpec(0.012, 0.0045, 0.018, half_z=True, path_depth=0.055, cut=True, rim=True)


def table_key(grid: SnapshotGrid, spec: RefSpec, nu: float, finger_radius: float,
              contact: str = DEFAULT_CONTACT, Jm: float = math.inf) -> str:
    """Cache key of a snapshot table. The displacement field does not depend on E (the contact penalty scales
    with E), so only ν enters, and a Gent solid's ``Jm`` (finite; a neo-Hookean key is the one it was before
    ``Jm`` existed); forces are scaled by E at run time. ``contact``: the finger's contact law
    (:data:`flexsheet.fem.reference.capsule_contact.CONTACT_LAWS`)."""
    import gmsh

    # spec.key() of a quarter spec leaves out ``cut`` (its azimuth-0 mesh does not depend on it); the off-axis
    # entries' meshes do
    return cache_key(TABLE_VERSION, solver_tag(contact),
                     *([UNLOAD_VERSION] if contact == "frictionless" else []),
                     grid.key(), spec.key(), f"cut={int(spec.cut)}",
                     gmsh.__version__, f"nu={nu:.9g}", f"r={finger_radius:.9g}",
                     *([f"Jm={Jm:.9g}"] if math.isfinite(Jm) else []))


def load_snapshot_table(cache, grid: SnapshotGrid, spec: RefSpec, material: Material, finger_radius: float,
                        contact: str = DEFAULT_CONTACT) -> dict | None:
    """The snapshot table of ``grid`` on ``spec``'s mesh for ``material`` and a finger of ``finger_radius`` m
    from ``cache`` (:class:`flexsheet.fem.cache.ArrayCache`: this machine's cache or the shipped store), or
    None — never built here (:func:`flexsheet.fem.reference.snapshot_build.load_or_build` builds one)."""
    return cache.load("snapshots", table_key(grid, spec, material.nu, finger_radius, contact, material.Jm))


def surface_coords(points: np.ndarray, radius: float, length: float, center: np.ndarray,
                   tol: float = 1e-6) -> dict[str, np.ndarray]:
    """Surface coordinates of ``points`` (S, 3) m on the cylinder: ``theta`` (S,) rad azimuth around +x toward
    +z, ``y`` (S,) m axial offset from the centre, ``rho`` (S,) m distance from the axis, ``cap`` (S,) bool
    (on an end face, |y| = L/2, and inside the rim: ρ < R − tol)."""
    rel = np.asarray(points, float) - np.asarray(center, float)
    theta = np.arctan2(rel[:, 2], rel[:, 0])
    rho = np.hypot(rel[:, 0], rel[:, 2])
    cap = (np.abs(np.abs(rel[:, 1]) - length / 2) < tol) & (rho < radius - tol)
    return {"theta": theta, "y": rel[:, 1], "rho": rho, "cap": cap}


class SnapshotModel:
    """Run-time look-up of a snapshot table (dict of arrays from
    :func:`flexsheet.fem.reference.snapshot_build.build_table`, e.g. from the cache).

    ``axial_max`` m: largest |axial offset| served (by translation along y); ``vertices`` (S, 3) m the
    rendered surface vertices (undeformed, display frame) whose displacements :meth:`surface` returns; ``E``
    Pa: the object's modulus (forces scale with E; displacements do not). Raises ``ValueError`` when the table
    is inconsistent.
    """

    def __init__(self, table: dict, vertices: np.ndarray, axial_max: float = 0.01, E: float | None = None):
        t = table
        if str(t.get("version", "")) != TABLE_VERSION:
            raise ValueError(f"snapshot table version {t.get('version')!r} != {TABLE_VERSION!r}")
        self.angles = np.asarray(t["angles"], float)
        self.depths = np.asarray(t["depths"], float)
        self.theta, self.ys, self.rhos = (np.asarray(t[k], float) for k in ("theta", "y", "rho"))
        self.side, self.cap = np.asarray(t["side"], np.float32), np.asarray(t["cap"], np.float32)
        na, nd = len(self.angles), len(self.depths)
        if self.side.shape != (na, nd, len(self.theta), len(self.ys), 3) or \
                self.cap.shape != (na, nd, len(self.theta), len(self.rhos), 3):
            raise ValueError(f"snapshot table shapes {self.side.shape}, {self.cap.shape} do not match its "
                             "axes")
        self.force = np.asarray(t["force"], float) * ((E / float(t["E"])) if E else 1.0)
        self.max_strain = np.asarray(t["max_strain"], float)
        self.inverted = np.asarray(t["inverted"], np.int64)
        self.radius, self.length = float(t["radius"]), float(t["length"])
        self.center = np.asarray(t["center"], float)
        self.axial_max = float(axial_max)
        sc = surface_coords(vertices, self.radius, self.length, self.center)
        self._th, self._y, self._rho, self._cap = sc["theta"], sc["y"], sc["rho"], sc["cap"]
        self._ysign = np.where(sc["y"] >= 0, 1.0, -1.0)
        self.n_vertices = len(vertices)
        # flattened fields for fast gathers: (na, nd, nθ·nY, 3)
        self._side_f = self.side.reshape(na, nd, -1, 3)
        self._cap_f = self.cap.reshape(na, nd, -1, 3)
        self.nbytes = self.side.nbytes + self.cap.nbytes

    @property
    def depth_max(self) -> float:
        """Deepest tabulated push, m."""
        return float(self.depths[-1])

    @property
    def angle_max(self) -> float:
        """Largest tabulated |azimuth|, rad."""
        return float(self.angles[-1])

    def covers(self, angle: float, depth: float, axial: float) -> bool:
        """True when (angle rad, depth m, axial m) lies inside the table (|angle| ≤ angle_max, 0 ≤ depth ≤
        depth_max, |axial| ≤ axial_max)."""
        return (abs(angle) <= self.angle_max + 1e-9 and 0.0 <= depth <= self.depth_max + 1e-12
                and abs(axial) <= self.axial_max)

    def _bracket(self, x: float, grid: np.ndarray) -> tuple[int, float]:
        if len(grid) == 1:
            return 0, 0.0
        j = int(np.clip(np.searchsorted(grid, x) - 1, 0, len(grid) - 2))
        w = float(np.clip((x - grid[j]) / (grid[j + 1] - grid[j]), 0.0, 1.0))
        return j, w

    def _weights(self, th: np.ndarray, s: np.ndarray, s_grid: np.ndarray):
        """Bilinear look-up weights at (θ, s) (k,) each on the (θ, ``s_grid``) grid: (rows (4, k) into a field
        (nθ·nS, 3), weights (4, k, 1), zero outside the θ range)."""
        tg = self.theta
        it = np.minimum(np.maximum(np.searchsorted(tg, th) - 1, 0), len(tg) - 2)
        wt = np.minimum(np.maximum((th - tg[it]) / (tg[it + 1] - tg[it]), 0.0), 1.0)
        js = np.minimum(np.maximum(np.searchsorted(s_grid, s) - 1, 0), len(s_grid) - 2)
        ws = np.minimum(np.maximum((s - s_grid[js]) / (s_grid[js + 1] - s_grid[js]), 0.0), 1.0)
        ns = len(s_grid)
        i00 = it * ns + js
        w = np.empty((4, len(th), 1))
        w[0, :, 0], w[1, :, 0], w[2, :, 0], w[3, :,
                                              0] = (1 - wt) * (1 - ws), (1 - wt) * ws, wt * (1 - ws), wt * ws
        w[:, (th < tg[0]) | (th > tg[-1])] = 0.0
        return np.array([i00, i00 + 1, i00 + ns, i00 + ns + 1]), w

    @staticmethod
    def _gather(fields, rows: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Σ over (weight, field) in ``fields`` of weight × the bilinear look-up (k, 3) at (``rows``,
        ``w``)."""
        g = 0.0
        for wj, f in fields:
            g = g + wj * f[rows]                   # (4, k, 3)
        return (g * w).sum(axis=0)

    def surface(self, angle: float, depth: float, axial: float = 0.0):
        """Surface displacements (S, 3) m of the rendered vertices for a push at azimuth ``angle`` (rad),
        ``depth`` (m), axial offset ``axial`` (m); plus (force N, stiffness dF/dd N/m, max strain, inverted).
        Raises ``ValueError`` when (angle, depth, axial) is outside the table (see :meth:`covers`)."""
        if not all(math.isfinite(v) for v in (angle, depth, axial)):
            raise ValueError(f"angle, depth, axial must be finite, got {angle!r}, {depth!r}, {axial!r}")
        if not self.covers(angle, depth, axial):
            raise ValueError(f"push (angle {math.degrees(angle):.1f} deg, depth {depth * 1e3:.1f} mm, axial "
                             f"{axial * 1e3:.1f} mm) is outside the snapshot table (|angle| <= "
                             f"{math.degrees(self.angle_max):.1f} deg, depth <= {self.depth_max * 1e3:.1f} "
                             f"mm, |axial| <= {self.axial_max * 1e3:.1f} mm)")
        mirror = angle < 0
        phi = abs(angle)
        th = -self._th if mirror else self._th
        yr = self._y - axial
        ya = np.abs(yr)
        ysg = np.where(yr >= 0, 1.0, -1.0)
        ia, wa = self._bracket(phi, self.angles)
        jd, wd = self._bracket(depth, self.depths)
        cap = self._cap
        side = ~cap
        js = [(j, wj) for j, wj in ((jd, 1.0 - wd), (jd + 1, wd)) if wj != 0.0 and j < len(self.depths)]
        u = np.zeros((self.n_vertices, 3))
        for i, wi in ((ia, 1.0 - wa), (ia + 1, wa)):
            if wi == 0.0 or i >= len(self.angles):
                continue
            delta = phi - self.angles[i]
            tl = th - delta
            ui = np.zeros((self.n_vertices, 3))
            if side.any():          # one set of look-up weights for both depths
                rows, w = self._weights(tl[side], ya[side], self.ys)
                ui[side] = self._gather([(wj, self._side_f[i, j]) for j, wj in js], rows, w)
            if cap.any():
                rows, w = self._weights(tl[cap], self._rho[cap], self.rhos)
                ui[cap] = self._gather([(wj, self._cap_f[i, j]) for j, wj in js], rows, w)
            cd, sd = math.cos(delta), math.sin(delta)
            ux, uz = ui[:, 0].copy(), ui[:, 2].copy()
            ui[:, 0] = cd * ux - sd * uz
            ui[:, 2] = sd * ux + cd * uz
            u += wi * ui
        u[:, 1] *= ysg
        if mirror:
            u[:, 2] *= -1.0
        # mirror images of the caps: the table holds the +y cap; a vertex on the −y cap uses it mirrored
        F = self._bilinear(self.force, ia, wa, jd, wd)
        j0 = min(jd, len(self.depths) - 2)
        dF0 = (self.force[ia, j0 + 1] - self.force[ia, j0]) / (self.depths[j0 + 1] - self.depths[j0])
        ib = min(ia + 1, len(self.angles) - 1)
        dF1 = (self.force[ib, j0 + 1] - self.force[ib, j0]) / (self.depths[j0 + 1] - self.depths[j0])
        k = (1 - wa) * dF0 + wa * dF1
        strain = self._bilinear(self.max_strain, ia, wa, jd, wd)
        inv = int(self.inverted[ia:ia + 2, jd:jd + 2].max())
        return u, float(max(F, 0.0)), float(max(k, 0.0)), float(strain), inv

    def _bilinear(self, tab: np.ndarray, ia: int, wa: float, jd: int, wd: float) -> float:
        return bilinear(tab, ia, wa, jd, wd)


def bilinear(tab: np.ndarray, ia: int, wa: float, jd: int, wd: float) -> float:
    """``tab`` (A, D) blended between rows ia, ia+1 by ``wa`` and columns jd, jd+1 by ``wd`` (clamped at the
    last row/column): the snapshot tables' per-push scalars (force, strain) at a push between samples."""
    ib = min(ia + 1, tab.shape[0] - 1)
    jb = min(jd + 1, tab.shape[1] - 1)
    return float((1 - wa) * ((1 - wd) * tab[ia, jd] + wd * tab[ia, jb])
                 + wa * ((1 - wd) * tab[ib, jd] + wd * tab[ib, jb]))
