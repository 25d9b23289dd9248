"""Nonlinear snapshots for the sphere scene: the cylinder's table (:mod:`flexsheet.fem.snapshots`,
Peterlík et al. 2010) carried over by the sphere's own symmetries.

A sphere held by its back half (support ``back_half``: every surface point behind the plane through the centre
normal to +x) is mapped onto itself, support included, by any rotation about the **support axis** e_a (+x
through the centre). A push along the inward normal at a surface point whose outward normal n makes the polar
angle α with e_a is therefore the push at α in one fixed plane — the stroke's plane (e_a, e_b), e_b the arc
stroke's ``toward`` direction made normal to e_a — rotated about e_a by ψ: **one parameter, α, plus the depth
d, describes every push exactly.** The stroke of ``sphere.yaml`` is that plane's arc from α = 0 to 60°.

* **Offline** (:func:`flexsheet.fem.reference.sphere_build.solve_alpha`): for each snapshot angle α_i
  (:class:`SphereGrid`, default 0–60° every 10°) the scene's hyperelastic body (the scene's law, Gent) on a
  gmsh mesh refined along that push path (:func:`flexsheet.fem.scene_mesh.scene_mesh` with ``refine_at``, full
  body, the scene's support) is pushed by the rigid frictionless capsule finger 0 → 50 mm
  (:func:`flexsheet.fem.reference.path_solver.solve_path_capsule`), the stable branch kept where the push is
  bistable (:func:`flexsheet.fem.reference.path_solver.stable_states`), and every depth sampled on a grid over
  the sphere in the stroke frame: θ (angle in the (e_a, e_b) plane from e_a, |θ| ≤ ``theta_max_deg``) × φ
  (latitude toward e_c = e_a × e_b), display-frame components.
* **Run time** (:meth:`SphereSnapshotModel.surface`): for a push with outward normal n at depth d, α = ∠(n,
  e_a) and ψ the rotation about e_a that takes the stroke plane to n. Each rendered vertex is rotated back by
  −ψ; for the two snapshot angles around α, the snapshot's field is rotated by δ_i = α − α_i within the plane
  (u(θ) ≈ Q(δ_i)·U_i(θ − δ_i), the cylinder's rotate-then-blend: about e_c this is *not* a symmetry — the
  support does not turn — so what the blend interpolates is the support's slow influence, as on the cylinder)
  and the two are blended linearly in α and in d; the result is rotated by ψ (exact). Force and stiffness
  dF/dd from the table's force, bilinear in (α, d).

Memory: float32, #α × #d × #θ × #φ × 3 × 4 bytes (≈ 64 MB for the default grid, 1° cells ≈ 0.62 mm on R 35
mm). Frames and units: display frame, m, N, rad (``_deg`` keys in degrees). Errors: ``ValueError`` naming the
field. This module is the run-time side (grid, frame, key, look-up); the solves and the table's assembly are
:mod:`flexsheet.fem.reference.sphere_build`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.cache import cache_key
from flexsheet.fem.reference.versions import SOLVER_VERSION, UNLOAD_VERSION
from flexsheet.fem.snapshots import bilinear

__all__ = ["SphereGrid", "SphereFrame", "sphere_frame", "SphereSnapshotModel", "SPHERE_TABLE_VERSION",
           "DEFAULT_SPHERE_GRID", "DEFAULT_SPHERE_SPEC", "grid_points", "sphere_table_key"]

SPHERE_TABLE_VERSION = "sphere-snap-1"


@dataclass(frozen=True)
class SphereGrid:
    """Sampling of a sphere table: ``alphas_deg`` snapshot polar angles (ascending, in [0, 90)), ``depth_max``
    m, ``depth_step`` m (load step and depth sample), ``dtheta_deg`` / ``dphi_deg`` the surface grid's cells,
    ``theta_max_deg`` the grid's reach from e_a (beyond it the held back half, zero). ``ValueError`` on bad
    values."""

    alphas_deg: tuple[float, ...] = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0)
    depth_max: float = 0.05
    depth_step: float = 0.0025
    dtheta_deg: float = 1.0
    dphi_deg: float = 1.0
    theta_max_deg: float = 100.0

    def __post_init__(self):
        a = np.asarray(self.alphas_deg, float)
        if a.ndim != 1 or len(a) == 0 or np.any(~np.isfinite(a)) or np.any(np.diff(a) <= 0) or a[0] < 0 \
                or a[-1] >= 90:
            raise ValueError(f"alphas_deg must be ascending, finite, in [0, 90), got {self.alphas_deg!r}")
        if not (math.isfinite(self.depth_max) and 0 < self.depth_max <= 0.07):
            raise ValueError(f"depth_max must be in (0, 0.07] m, got {self.depth_max!r}")
        if not (math.isfinite(self.depth_step) and 0 < self.depth_step <= self.depth_max):
            raise ValueError(f"depth_step must be in (0, depth_max] m, got {self.depth_step!r}")
        for name in ("dtheta_deg", "dphi_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v <= 10):
                raise ValueError(f"{name} must be in (0, 10], got {v!r}")
        if not (math.isfinite(self.theta_max_deg) and 90 <= self.theta_max_deg <= 180):
            raise ValueError(f"theta_max_deg must be in [90, 180], got {self.theta_max_deg!r}")

    def key(self) -> str:
        """Text that fixes the grid (for cache keys)."""
        return (f"a={','.join(f'{x:g}' for x in self.alphas_deg)},dmax={self.depth_max:g},dstep="
                f"{self.depth_step:g},dth={self.dtheta_deg:g},dph={self.dphi_deg:g},thmax="
                f"{self.theta_max_deg:g}")

    def depths(self) -> np.ndarray:
        """(D,) m: 0, step, … depth_max."""
        return np.round(np.arange(0, int(round(self.depth_max / self.depth_step)) + 1) * self.depth_step, 9)

    def thetas(self) -> np.ndarray:
        """(T,) rad, −theta_max … theta_max."""
        n = int(round(self.theta_max_deg / self.dtheta_deg))
        return np.radians(np.arange(-n, n + 1) * self.dtheta_deg)

    def phis(self) -> np.ndarray:
        """(P,) rad, −90° … 90°."""
        n = int(round(90.0 / self.dphi_deg))
        return np.radians(np.linspace(-90.0, 90.0, 2 * n + 1))


DEFAULT_SPHERE_GRID = SphereGrid()
#: the table's mesh: (h, h_fine, refine_radius, path_depth) m — h_fine 4.5
#: mm along the push path (the cylinder's next-to-finest level but one, for
#: the build's time), the tube to 55 mm deep as the cylinder's reference
DEFAULT_SPHERE_SPEC = (0.012, 0.0045, 0.015, 0.055)


@dataclass(frozen=True)
class SphereFrame:
    """The sphere's symmetry frame: ``center`` (3,) m, ``radius`` m, ``axes`` (3, 3) rows e_a (support axis,
    +x), e_b (the stroke plane's second axis), e_c = e_a × e_b."""

    center: np.ndarray
    radius: float
    axes: np.ndarray

    def direction(self, alpha: float) -> np.ndarray:
        """Outward unit normal (3,) at polar angle ``alpha`` rad in the stroke plane."""
        return math.cos(alpha) * self.axes[0] + math.sin(alpha) * self.axes[1]

    def angles_of(self, normal) -> tuple[float, float]:
        """(α, ψ) rad of an outward normal (3,): α = ∠(n, e_a) ∈ [0, π], ψ the rotation about e_a taking
        the stroke plane's half-plane (e_b side) to n (0 when n ∥ e_a)."""
        n = np.asarray(normal, float)
        n = n / np.linalg.norm(n)
        a, b, c = self.axes @ n
        return math.acos(max(-1.0, min(1.0, a))), (math.atan2(c, b) if b * b + c * c > 1e-24 else 0.0)


def sphere_frame(scene) -> SphereFrame:
    """The symmetry frame of ``scene`` (a :class:`flexsheet.model.scenes.Scene`) when the table applies: a
    sphere, ``back_half`` support, no inclusions, an arc stroke about the sphere's centre starting on the
    support axis (+x). Raises ``ValueError`` naming what breaks the symmetry."""
    o = scene.object
    if o.kind != "sphere":
        raise ValueError(f"object.kind must be 'sphere' for a sphere table, got {o.kind!r}")
    if scene.support.kind != "back_half":
        raise ValueError("support.kind must be 'back_half' (rotations about +x keep it), got "
                         f"{scene.support.kind!r}")
    if scene.inclusions:
        raise ValueError(f"inclusions break the sphere's symmetry: {len(scene.inclusions)} given")
    st = scene.stroke
    if st.kind != "arc":
        raise ValueError(f"stroke.kind must be 'arc' for a sphere table, got {st.kind!r}")
    c = np.asarray(scene.center, float)
    if st.center is not None and np.linalg.norm(np.asarray(st.center, float) - c) > 1e-9:
        raise ValueError(f"stroke.center must be the sphere's centre {c.tolist()}, got {list(st.center)}")
    ea = np.array([1.0, 0.0, 0.0])
    s = np.asarray(st.start, float) / np.linalg.norm(st.start)
    if s @ ea < 1 - 1e-9:
        raise ValueError(f"stroke.start must point along +x (the support axis), got {list(st.start)}")
    t = np.asarray(st.toward, float)
    eb = t - (t @ ea) * ea
    eb /= np.linalg.norm(eb)
    return SphereFrame(c, float(o.radius), np.stack([ea, eb, np.cross(ea, eb)]))


def grid_points(frame: SphereFrame, grid: SphereGrid) -> np.ndarray:
    """(T·P, 3) m: the grid's points on the sphere, θ-major (display frame)."""
    T, P = np.meshgrid(grid.thetas(), grid.phis(), indexing="ij")
    loc = np.stack([np.cos(P) * np.cos(T), np.cos(P) * np.sin(T), np.sin(P)], axis=-1).reshape(-1, 3)
    return frame.center + frame.radius * loc @ frame.axes


class SphereSnapshotModel:
    """Run-time look-up of a sphere table (:func:`flexsheet.fem.reference.sphere_build.assemble_table`) at the
    rendered ``vertices`` (S, 3) m (rest, display frame); ``E`` Pa: the object's modulus (forces scale with
    it). ``ValueError`` when the table is inconsistent."""

    def __init__(self, table: dict, vertices: np.ndarray, E: float | None = None):
        t = table
        if str(t.get("version", "")) != SPHERE_TABLE_VERSION:
            raise ValueError(f"sphere table version {t.get('version')!r} != {SPHERE_TABLE_VERSION!r}")
        self.alphas, self.depths = np.asarray(t["alphas"], float), np.asarray(t["depths"], float)
        self.theta, self.phi = np.asarray(t["theta"], float), np.asarray(t["phi"], float)
        self.field = np.asarray(t["field"], np.float32)
        if self.field.shape != (len(self.alphas), len(self.depths), len(self.theta), len(self.phi), 3):
            raise ValueError(f"sphere table field {self.field.shape} does not match its axes")
        self.force = np.asarray(t["force"], float) * ((E / float(t["E"])) if E else 1.0)
        self.max_strain, self.inverted = np.asarray(t["max_strain"], float), np.asarray(t["inverted"],
                                                                                        np.int64)
        self.frame = SphereFrame(np.asarray(t["center"], float), float(t["radius"]),
                                 np.asarray(t["axes"], float))
        v = np.asarray(vertices, float) - self.frame.center
        self._loc = v @ self.frame.axes.T                       # (S, 3) stroke-frame components (a, b, c)
        self._r = np.linalg.norm(v, axis=1)
        self._dth = float(self.theta[1] - self.theta[0])
        self._dph = float(self.phi[1] - self.phi[0])

    @property
    def depth_max(self) -> float:
        """Deepest push served, m."""
        return float(self.depths[-1])

    def radial_push(self, tip) -> tuple[np.ndarray, float]:
        """(outward unit normal (3,), depth m) of the radial push whose leading point is ``tip`` (3,) m: the
        push the table holds, exactly where the finger is (a contact normal taken from a surface sample nearby
        is ~1° off on the scene's surface index, which moves the dent ~0.6 mm)."""
        rel = np.asarray(tip, float) - self.frame.center
        r = float(np.linalg.norm(rel))
        return (rel / r if r > 1e-12 else self.frame.axes[0].copy()), self.frame.radius - r

    def covers(self, normal, depth: float) -> bool:
        """Whether a push with outward ``normal`` (3,) at ``depth`` m lies in the table."""
        a, _ = self.frame.angles_of(normal)
        return 0.0 < depth <= self.depth_max + 1e-12 and a <= self.alphas[-1] + 1e-9

    @staticmethod
    def _bracket(x: float, grid: np.ndarray) -> tuple[int, float]:
        if len(grid) == 1:
            return 0, 0.0
        i = int(np.clip(np.searchsorted(grid, x, side="right") - 1, 0, len(grid) - 2))
        return i, float(np.clip((x - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0))

    def _field_at(self, ia: int, jd: int, wd: float, th: np.ndarray, ph: np.ndarray) -> np.ndarray:
        """(S, 3) display-frame displacement of snapshot ``ia`` blended between depths jd, jd+1 at grid
        coordinates (θ, φ); zero outside the θ range (the held back half)."""
        ft = (th - self.theta[0]) / self._dth
        fp = (ph - self.phi[0]) / self._dph
        inside = (ft >= 0) & (ft <= len(self.theta) - 1)
        i0 = np.clip(np.floor(ft).astype(np.int64), 0, len(self.theta) - 2)
        k0 = np.clip(np.floor(fp).astype(np.int64), 0, len(self.phi) - 2)
        wt = np.clip(ft - i0, 0.0, 1.0)[:, None]
        wp = np.clip(fp - k0, 0.0, 1.0)[:, None]
        out = 0.0
        for j, w in ((jd, 1.0 - wd), (min(jd + 1, len(self.depths) - 1), wd)):
            if w == 0.0:
                continue
            F = self.field[ia, j]
            out = out + w * ((1 - wt) * ((1 - wp) * F[i0, k0] + wp * F[i0, k0 + 1])
                             + wt * ((1 - wp) * F[i0 + 1, k0] + wp * F[i0 + 1, k0 + 1]))
        return np.where(inside[:, None], out, 0.0)

    def surface(self, normal, depth: float) -> tuple[np.ndarray, float, float, float, int]:
        """(displacements (S, 3) m at the vertices, force N, stiffness dF/dd N/m, largest strain, inverted
        elements) for a push with outward unit ``normal`` (3,) at ``depth`` m (the caller checks
        :meth:`covers`)."""
        alpha, psi = self.frame.angles_of(normal)
        ax = self.frame.axes
        cp, sp = math.cos(psi), math.sin(psi)
        a, b, c = self._loc.T
        b1, c1 = cp * b + sp * c, -sp * b + cp * c              # the vertices rotated back by −ψ about e_a
        th = np.arctan2(b1, a)
        ph = np.arcsin(np.clip(c1 / np.maximum(self._r, 1e-12), -1.0, 1.0))
        ia, wa = self._bracket(alpha, self.alphas)
        jd, wd = self._bracket(depth, self.depths)
        u = np.zeros((len(a), 3))
        for i, w in ((ia, 1.0 - wa), (min(ia + 1, len(self.alphas) - 1), wa)):
            if w == 0.0:
                continue
            delta = alpha - self.alphas[i]
            U = self._field_at(i, jd, wd, th - delta, ph) @ ax.T   # stroke-frame components
            cd, sd = math.cos(delta), math.sin(delta)
            ua, ub = cd * U[:, 0] - sd * U[:, 1], sd * U[:, 0] + cd * U[:, 1]    # rotated by δ in the plane
            u[:, 0] += w * ua
            u[:, 1] += w * (cp * ub - sp * U[:, 2])                              # then by ψ about e_a
            u[:, 2] += w * (sp * ub + cp * U[:, 2])
        u = u @ ax
        f = bilinear(self.force, ia, wa, jd, wd)
        j1 = min(jd + 1, len(self.depths) - 1)
        stiff = (bilinear(self.force, ia, wa, j1, 0.0) - bilinear(self.force, ia, wa, jd, 0.0)) / \
            max(self.depths[j1] - self.depths[jd], 1e-12)
        strain = bilinear(self.max_strain, ia, wa, jd, wd)
        inv = int(max(self.inverted[ia, jd], self.inverted[min(ia + 1, len(self.alphas) - 1), j1]))
        return u, float(f), float(stiff), float(strain), inv


def sphere_table_key(scene, grid: SphereGrid = DEFAULT_SPHERE_GRID, spec=DEFAULT_SPHERE_SPEC) -> str:
    """Cache key (kind "spheresnap") of ``scene``'s table: the scene's values (:meth:`Scene.key`, its material
    included), the grid, the mesh sizes, gmsh's version and the solver's versions — what the FEM node looks
    up."""
    import gmsh

    return cache_key(SPHERE_TABLE_VERSION, scene.key(), grid.key(), *(f"{x:.9g}" for x in spec),
                     gmsh.__version__,
                     SOLVER_VERSION, UNLOAD_VERSION)
