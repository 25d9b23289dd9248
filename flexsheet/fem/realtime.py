"""The real-time FEM model the node runs (pure apart from its optional disk cache of precomputed arrays).

:class:`RealtimeModel` = mesh + linear P2 model + capacitance solver (James & Pai 2001) over the candidate
contact region, with the full sparse solve as fallback when the finger leaves that region, failure checks on
the part of the strain-monitor zone (surface + interior nodes near the contact region) near the finger, and
the geometrically nonlinear mode:

* **nonlinear snapshots** (:mod:`flexsheet.fem.snapshots`, Peterlík et al. 2010): hyperelastic (neo-Hookean or
  Gent) reference solutions (:mod:`flexsheet.fem.reference.hyperelastic`) precomputed over (contact azimuth,
  depth), rotated with the finger and interpolated per update. When attached
  (:meth:`RealtimeModel.attach_snapshots`) and the push lies in the table, this is what the node draws
  (``method = "snapshots"``); the linear model serves everything else.
* the older corotational depth table (Niroomandi et al. 2013 / Filipovič & Peterlík 2009 with corotational FEM
  offline; unvalidated, off by default).

All precomputed arrays go through :class:`flexsheet.fem.cache.ArrayCache`.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache, cache_key
from flexsheet.fem.contact import ContactFinger, finger_at, finger_from_tip
from flexsheet.fem.corotational import solve_corotational
from flexsheet.fem.deformation_checks import TetChecks, element_checks, fold_operator
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, TetMesh, arc_points, cylinder_tet_mesh
from flexsheet.fem.snapshots import SnapshotModel
from flexsheet.fem.solver import CapacitanceSolver, FemModel, OutsideCandidates, solve_full

log = logging.getLogger(__name__)

__all__ = ["RealtimeModel", "Update", "CondensedSurface", "dist_to_points"]

_CACHE_VERSION = "2"


@dataclass
class Update:
    """One model update. ``vertices`` (S, 3) float32 m display frame (deformed surface; undeformed when
    ``valid`` is False); ``force`` N; ``stiffness`` N/m; ``depth`` m; ``contact_point`` (3,) m; ``method``;
    ``max_strain``; ``inverted`` element count; ``status``; ``valid``.

    Policy: inverted elements or strain over the limit → status ``linear_invalid:<reason>`` (or the
    corotational table's answer, status ``nonlinear:...``); the deformation is still drawn (``valid``) unless
    a rendered surface triangle folds over or a value is not finite — then ``valid`` is False, the vertices
    are the rest shape and force/stiffness are 0."""

    vertices: np.ndarray
    force: float
    stiffness: float
    depth: float
    contact_point: np.ndarray
    method: str
    max_strain: float
    inverted: int
    status: str
    valid: bool


class CondensedSurface:
    """What a condensed real-time model (``self.mesh``, ``self.solver``: :class:`CapacitanceSolver`,
    ``self.model``) shares, the cylinder's (:class:`RealtimeModel`) and any scene's
    (:class:`flexsheet.fem.scene_model.SceneModel`): the rendered-surface and strain-monitor index maps, the
    rest surface, the condensed solve (both subclasses load it in single precision:
    :meth:`CapacitanceSolver.from_arrays`) with its sparse fallback, the strain and inversion check near the
    finger, the scatter to surface vertices, the fold check."""

    @staticmethod
    def _check_params(finger_radius: float, max_depth: float, strain_limit: float) -> None:
        """Raise ``ValueError`` naming the field unless finger radius ∈ [1, 30] mm, max depth ∈ (0, 70] mm and
        strain limit > 0 (both models' constructors)."""
        if not (math.isfinite(finger_radius) and 0.001 <= finger_radius <= 0.03):
            raise ValueError(f"finger_radius must be in [0.001, 0.03] m, got {finger_radius!r}")
        if not (math.isfinite(max_depth) and 0.0 < max_depth <= 0.07):
            raise ValueError(f"max_depth must be in (0, 0.07] m, got {max_depth!r}")
        if not (math.isfinite(strain_limit) and strain_limit > 0):
            raise ValueError(f"strain_limit must be > 0, got {strain_limit!r}")

    def _set_output_maps(self, monitor: np.ndarray) -> None:
        """Set ``n_candidates``, ``surface_nodes`` (S,), ``faces`` (F, 3) int32 into them, ``_rest`` (S, 3)
        float32 m, ``_rest_normals`` (F, 3), ``_surf_in_out`` (S,) output row of each surface node (−1: a
        support node, zero displacement), ``_mon_tets`` the monitored tetrahedra (all four nodes are outputs
        and ``monitor`` (N,) bool holds them) in output rows, ``_out_points`` and ``_tet_checks`` (their
        precomputed :class:`flexsheet.fem.deformation_checks.TetChecks`)."""
        m = self.mesh
        self.n_candidates = len(self.solver.cand_pts)
        self.surface_nodes = m.surface_nodes
        self.faces = np.searchsorted(self.surface_nodes, m.faces).astype(np.int32)
        self._rest = m.points[self.surface_nodes].astype(np.float32)
        q = m.points[m.faces]
        self._rest_normals = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
        out_idx = np.full(len(m.points), -1, np.int64)
        out_idx[self.solver.out_pts] = np.arange(len(self.solver.out_pts))
        self._surf_in_out = out_idx[self.surface_nodes]
        tet_ok = np.all(out_idx[m.tets] >= 0, axis=1) & np.all(monitor[m.tets], axis=1)
        self._mon_tets = out_idx[m.tets[tet_ok]]
        self._out_points = m.points[self.solver.out_pts]
        self._tet_checks = TetChecks(self._out_points, self._mon_tets)
        # per-update helpers: the surface gather (support rows point at an appended zero row) and the fold
        # test as one sparse product (see folded_faces)

        self._surf_take = np.where(self._surf_in_out >= 0, self._surf_in_out, len(self.solver.out_pts))
        self._fold_op, self._fold_rest = fold_operator(self._rest.astype(np.float64), self.faces,
                                                       self._rest_normals)

    @property
    def rest_vertices(self) -> np.ndarray:
        """Undeformed rendered surface vertices (S, 3) float32 m, display frame (a copy)."""
        return self._rest.copy()

    @property
    def n_nodes(self) -> int:
        """Mesh node count."""
        return len(self.mesh.points)

    def _solve(self, fg: ContactFinger, outputs: bool = True):
        """(solution, displacements (O, 3) m of the output points, method): the condensed solve, or the full
        sparse one ("sparse") when the contact leaves the precomputed candidates. ``outputs`` False: the
        condensed solve returns no displacements ((0, 3): force and dF/dd only)."""
        try:
            sol = self.solver.solve(fg, outputs)
            return sol, sol.u, "condensed"
        except OutsideCandidates:
            sol = solve_full(self.model, fg)
            u_out = sol.u[self.solver.out_pts]
            sol.u_full = None
            return sol, u_out, "sparse"

    def _checks(self, fg: ContactFinger, u_out: np.ndarray) -> tuple[float, int]:
        """(max principal strain, inverted elements) over the monitor tets whose centroid lies within finger
        radius + depth + 2·h_fine of the undeformed surface point under the sphere (where strain concentrates;
        the rest of the monitor zone is not checked: over the cylinder's ±60° arc, 0–50 mm and three axial
        offsets this gave the same strain and inverted count as checking every monitor tet, 2026-11-23, for
        fingers not held), by the precomputed :class:`flexsheet.fem.deformation_checks.TetChecks`. ``u_out``
        (O, 3) m output-point displacements."""
        tc = self._tet_checks
        if tc.n_tets == 0:
            return 0.0, 0
        # centred under the sphere as it is now (for a held finger, whose contact point stays at the anchor
        # while the sphere slides, the anchor would go stale); for a finger not held this is its contact point
        at = np.asarray(fg.center, float) + np.asarray(fg.direction, float) * (fg.radius - fg.depth)
        return tc(u_out, tc.near(at, self.finger_radius + fg.depth + 2 * self.spec.h_fine))

    def _surface_of(self, u_out: np.ndarray) -> np.ndarray:
        """Surface-vertex displacements (S, 3) m from output-point displacements ``u_out`` (O, 3) m (support
        vertices 0)."""
        pad = np.zeros((len(u_out) + 1, 3))
        pad[:-1] = u_out
        return pad[self._surf_take]

    def folded_faces(self, us: np.ndarray) -> int:
        """Number of rendered surface triangles whose normal turned by more than 90° (the drawn surface folds
        over itself: garbage to draw). ``us`` (S, 3) m surface-vertex displacements.

        With x = rest + us, face edges e1 = x1 − x0, e2 = x2 − x0 and rest normal n0, the turned normal's
        component along n0 is (e1 × e2)·n0 = e2·(n0 × e1): both factors are linear in ``us``, so one
        precomputed sparse product gives them for every face
        (:func:`flexsheet.fem.deformation_checks.fold_operator`)."""
        nf = len(self.faces)
        y = self._fold_op @ np.ascontiguousarray(us, np.float64).reshape(-1) + self._fold_rest
        dot = (y[:3 * nf] * y[3 * nf:]).reshape(3, nf).sum(axis=0)
        return int(np.count_nonzero(dot <= 0.0))


class RealtimeModel(CondensedSurface):
    """Real-time cylinder model.

    Parameters: ``spec`` mesh resolution; ``order`` element order of the capacitance model (2: P2, whose
    edge-midpoint DOFs also take contact; outputs are the mesh's corner nodes); ``material``;
    ``finger_radius`` m; ``max_depth`` m (deeper input is rejected); ``strain_limit`` (largest principal small
    strain beyond which linear is declared invalid); ``cache_dir`` (None: no disk cache); ``reach`` m extra
    margin around the working arc for candidate contact points (default finger_radius + 2 mm). Progress is
    logged. Raises ``ValueError`` on bad parameters. ``precompute_s`` and ``cache_hit`` tell how start-up
    went.
    """

    def __init__(self, spec: MeshSpec, material: Material, finger_radius: float = 0.008,
                 max_depth: float = 0.05,
                 strain_limit: float = 1.0, cache_dir: str | None = DEFAULT_CACHE_DIR,
                 reach: float | None = None,
                 order: int = 2):
        self._check_params(finger_radius, max_depth, strain_limit)
        t0 = time.perf_counter()
        self.spec, self.material, self.order = spec, material, order
        self.finger_radius, self.max_depth, self.strain_limit = finger_radius, max_depth, strain_limit
        reach = finger_radius + 0.002 if reach is None else reach
        import gmsh

        # the linear (capacitance) model reads E and ν only: a Gent solid shares the neo-Hookean key
        small_strain = Material(material.E, material.nu)
        self.cache_key = cache_key(_CACHE_VERSION, spec.key(), gmsh.__version__, small_strain.key(),
                                   f"{reach:.9g}",
                                   f"{finger_radius:.9g}", f"P{order}")
        self.cache = ArrayCache(cache_dir)
        self._model = self._p1 = None
        self._reach = reach
        z, self.cache_hit, _ = self.cache.get_or_compute("capacitance", self.cache_key, self._precompute,
                                                         "capacitance matrices")
        try:
            self.mesh = TetMesh(z["points"], z["tets"], z["faces"], z["fixed"], spec)
            # single precision per update, as the scenes' (CapacitanceSolver.from_arrays)
            self.solver = CapacitanceSolver.from_arrays(z, dtype=np.float32)
            monitor = z["monitor"]
        except (KeyError, ValueError) as exc:
            raise ValueError(f"capacitance cache entry {self.cache_key} is inconsistent: {exc}") from exc
        self._set_output_maps(monitor)
        self.nonlinear = None
        self.snapshots = None
        self._anchor = None
        self.precompute_s = time.perf_counter() - t0

    def attach_snapshots(self, table: dict, axial_max: float = 0.01) -> None:
        """Serve pushes inside the nonlinear snapshot ``table``
        (:func:`flexsheet.fem.reference.snapshot_build.build_table`) from it; raises ``ValueError`` when the
        table is inconsistent. Thread-safe to call while updates run (the model is swapped in one
        assignment)."""
        self.snapshots = SnapshotModel(table, self._rest.astype(np.float64), axial_max=axial_max,
                                       E=self.material.E)

    def _precompute(self) -> dict:
        """Mesh, candidate/output/monitor sets and the capacitance matrices (the cache entry's arrays)."""
        spec, order, reach = self.spec, self.order, self._reach
        self.mesh = cylinder_tet_mesh(spec)
        m = self.mesh
        model = self.model
        arc = arc_points(m.radius, m.center, spec.arc_deg, 0.001)
        dist = dist_to_points(model.points, arc)
        surf = model.boundary & ~model.fixed
        candidates = surf & (dist <= reach)
        monitor = (dist <= reach + 2 * spec.h_fine)[:len(m.points)]
        corner = np.arange(len(model.points)) < len(m.points)
        outputs = (surf | (np.pad(monitor, (0, len(model.points) - len(m.points))) & ~model.fixed)) & corner
        log.info(f"fem: precomputing capacitance matrices for {int(candidates.sum())} candidate contact "
                  f"points on a {len(m.points)}-node P{order} mesh ...")
        solver = CapacitanceSolver(model, candidates, outputs)
        return {"points": m.points, "tets": m.tets, "faces": m.faces, "fixed": m.fixed, "monitor": monitor,
                **solver.arrays()}

    @property
    def model(self) -> FemModel:
        """The assembled FEM model (built on first use after a cache hit: the sparse fallback needs it)."""
        if self._model is None:
            self._model = FemModel(self.mesh, self.material, order=self.order)
            if self.order == 1:
                self._p1 = self._model
        return self._model

    @property
    def p1_model(self) -> FemModel:
        """P1 model on the same mesh (built on first use; the corotational table needs it)."""
        if self._p1 is None:
            self._p1 = self.model if self.order == 1 else FemModel(self.mesh, self.material, order=1)
        return self._p1

    def build_nonlinear_table(self, depths: np.ndarray | None = None) -> None:
        """Precompute corotational surface displacements at ``depths`` (m, ascending from 0) for pushes at
        the working-arc points (azimuth samples every 10°). Slow (seconds per depth): call it off the
        real-time path. Sets ``self.nonlinear``."""
        if depths is None:
            depths = np.linspace(0.0, self.max_depth, 11)
        depths = np.asarray(depths, float)
        nang = max(1, int(round(2 * self.spec.arc_deg / 10.0)) + 1)
        angles = (np.radians(np.linspace(-self.spec.arc_deg, self.spec.arc_deg, nang)) if nang > 1
                  else np.zeros(1))
        U = np.zeros((len(angles), len(depths), len(self.surface_nodes), 3), np.float32)
        F = np.zeros((len(angles), len(depths)))
        inv = np.zeros((len(angles), len(depths)), np.int64)
        for i, ang in enumerate(angles):
            u0 = None
            for j, d in enumerate(depths):
                if d <= 0:
                    continue
                fg = finger_at(float(ang), float(d), self.finger_radius, self.mesh.radius, self.mesh.center)
                sol, _, _ = solve_corotational(self.p1_model, fg, u0=u0)
                u0 = sol.u
                U[i, j] = sol.u[self.surface_nodes]
                F[i, j] = sol.force
                _, inv[i, j] = element_checks(self.mesh.points, self.mesh.tets, sol.u)
                log.info(f"fem: corotational table angle {math.degrees(ang):.0f} deg depth {d * 1e3:.0f} mm "
                    f"force {sol.force:.3f} N")
        self.nonlinear = {"angles": angles, "depths": depths, "U": U, "F": F, "inverted": inv}

    def update(self, tip: np.ndarray) -> Update:
        """Deform the object for fingertip position ``tip`` (3,) m display frame.

        Stateful: while the finger is pressed ≥ 5 mm the contact point is held (:func:`finger_from_tip`).
        Raises ``ValueError`` (from :func:`finger_from_tip`) for NaN/inf, out-of-object or too-deep input.
        Never returns non-finite vertices: a failed linear solve gives ``valid=False`` with the rest shape."""
        fg = finger_from_tip(tip, self.finger_radius, self.mesh.radius, self.mesh.length, self.mesh.center,
                             self.max_depth, anchor=self._anchor)
        self._anchor = fg if fg.depth > 0 else None
        return self.update_finger(fg)

    def reset(self) -> None:
        """Forget the held contact point (see ``anchor`` in :func:`finger_from_tip`)."""
        self._anchor = None

    def update_finger(self, fg: ContactFinger) -> Update:
        """As :meth:`update` for a prepared :class:`ContactFinger`: the nonlinear snapshots when attached and
        the push lies in their table, the linear model otherwise."""
        snap = self.snapshots
        if snap is not None and fg.depth > 0 and snap.covers(fg.angle, fg.depth, fg.axial):
            return self._update_snapshots(snap, fg)
        return self._update_linear(fg)

    def _update_snapshots(self, snap, fg: ContactFinger) -> Update:
        us, force, stiff, strain, inv = snap.surface(fg.angle, fg.depth, fg.axial)
        if not (np.all(np.isfinite(us)) and math.isfinite(force) and math.isfinite(stiff)):
            return Update(self._rest.copy(), 0.0, 0.0, fg.depth, fg.contact_point.copy(), "snapshots", 0.0, 0,
                          "nonlinear_invalid:non_finite", False)
        status = "ok" if inv == 0 else f"nonlinear_invalid:inverted={inv}"
        verts = (self._rest + us.astype(np.float32)).astype(np.float32)
        return Update(verts, force, stiff, fg.depth, fg.contact_point.copy(), "snapshots", strain, inv,
                      status,
                      True)

    def _update_linear(self, fg: ContactFinger) -> Update:
        sol, u_out, method = self._solve(fg)
        strain, inv = self._checks(fg, u_out) if sol.n_contact else (0.0, 0)
        us = self._surface_of(u_out)
        finite = bool(np.all(np.isfinite(us))) and math.isfinite(sol.force) and math.isfinite(sol.stiffness)
        status, valid = "ok", True
        force, stiff = sol.force, sol.stiffness
        if not finite:
            status, valid = "linear_invalid:non_finite", False
        elif inv > 0 or strain > self.strain_limit:
            reason = f"inverted={inv}" if inv > 0 else f"strain={strain:.2f}>{self.strain_limit:g}"
            nl = self._nonlinear_lookup(fg)
            if nl is not None and nl[3] == 0:
                us, force, stiff = nl[0], nl[1], nl[2]
                status, method = f"nonlinear:corotational table ({reason} in linear)", "corotational"
            else:
                status = f"linear_invalid:{reason}"
        if valid:
            folded = self.folded_faces(us)
            if folded:
                status, valid = f"linear_invalid:folded_surface={folded}" + (
                    f";{status.split(':', 1)[1]}" if status.startswith("linear_invalid") else ""), False
        verts = self._rest + (us.astype(np.float32) if valid else 0.0)
        return Update(verts.astype(np.float32), float(force) if valid else 0.0,
                      float(stiff) if valid else 0.0,
                      fg.depth, fg.contact_point.copy(), method, float(strain), int(inv), status, valid)

    def _nonlinear_lookup(self, fg: ContactFinger):
        t = self.nonlinear
        if t is None:
            return None
        i = int(np.argmin(np.abs(t["angles"] - fg.angle)))
        if abs(t["angles"][i] - fg.angle) * self.mesh.radius > 0.002 or abs(fg.axial) > 0.002:
            return None
        d = t["depths"]
        if fg.depth > d[-1]:
            return None
        j = int(np.clip(np.searchsorted(d, fg.depth) - 1, 0, len(d) - 2))
        w = (fg.depth - d[j]) / (d[j + 1] - d[j])
        U = (1 - w) * t["U"][i, j] + w * t["U"][i, j + 1]
        F = (1 - w) * t["F"][i, j] + w * t["F"][i, j + 1]
        k = (t["F"][i, j + 1] - t["F"][i, j]) / (d[j + 1] - d[j])
        return U, float(F), float(max(k, 0.0)), int(max(t["inverted"][i, j], t["inverted"][i, j + 1]))


def dist_to_points(x: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance (N,) m from each row of ``x`` (N, 3) m to the nearest row of ``pts`` (K, 3) m."""
    from scipy.spatial import cKDTree

    return cKDTree(pts).query(x)[0]
