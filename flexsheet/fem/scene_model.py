"""The real-time FEM model of any scene: sphere, rounded box, organ with its stiff inclusion (pure
apart from its optional disk cache of precomputed arrays).

:class:`SceneModel` = the scene's tetrahedral mesh (:func:`flexsheet.fem.scene_mesh.scene_mesh`, refined along
the stroke path) + linear elasticity with per-element material (:class:`flexsheet.fem.solver.FemModel` with
the scene's support and ``E_elem``/``nu_elem``: the inclusions) + the capacitance solver (James & Pai 2001,
:class:`flexsheet.fem.solver.CapacitanceSolver`) over the free surface DOF points within ``reach`` of the
stroke path, with the full sparse solve (:func:`flexsheet.fem.solver.solve_full`) wherever the finger touches
outside that region.

Contact (:func:`scene_finger`): the fingertip is a rigid sphere of radius r whose leading point is ``tip``.
The contact point is ``tip``'s projection onto the scene's surface — the tangent plane at the nearest of a
dense set of surface samples (the scene's own surface mesh's vertices and face centroids, with
:meth:`Scene.surface_point` normals; a KD-tree query, ~20 µs) — the push direction p̂ is the inward normal
there and the depth d = (q − tip)·n. Surface nodes inside the sphere get the imposed displacement onto its
leading surface (:func:`flexsheet.fem.contact.imposed_displacement`, bonded Dirichlet contact). While pressed
≥ 5 mm the contact point and direction are held (a pressed finger does not slide; deep pushes stay defined).
``ContactFinger.angle`` and ``ContactFinger.axial`` are 0 for scenes (they are the cylinder's coordinates).

Outputs per update (:class:`flexsheet.fem.realtime.Update`): the deformed surface (the mesh's boundary corner
nodes, float32 m, display frame), the contact force N and the local stiffness dF/dd N/m (the contact set
held; what the planner sets the sheet's tension from), max strain and inverted elements in a monitor zone
around the stroke, status/valid as the cylinder's model. A touch lighter than :data:`STIFFNESS_FLOOR`
(0.5 mm) reports the stiffness of a press that deep at the same point (one more capacitance solve): the few
surface nodes a grazing finger touches give a stiffness that jumps from 0 to tens of N/m with the
fingertip's measurement noise, which would make the sheet's tension flicker (the planner's estimate uses
the same floor, ``min_contact_depth``).

Cost per update (≥ 1 kHz): the condensed solve in single precision (G_aa gathered with one flat
index, LAPACK ``spotrf``/``spotrs``, u = G_oaᵀ f; displacements within 0.05 µm of a float64 solve), the
strain/inversion checks as one sparse gradient product plus exact bounds that leave few tets for the
eigenvalues (:class:`flexsheet.fem.deformation_checks.TetChecks`), the fold test as one sparse product
(:func:`flexsheet.fem.deformation_checks.fold_operator`): ~0.3 ms on the organ, 1 BLAS thread.

The stiffness is the held-contact-set dF/dd of the imposed-overlap contact: on a sphere ≈ 1.4 × Hertz's
tangent stiffness 2E*·a (the overlap's circle is √2·a; docs/scenes.md), and the force ≈ Hertz/√2.

Frames and units: display frame, m, N, N/m, Pa. Errors: ``ValueError`` naming the argument.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache, cache_key
from flexsheet.fem.contact import ContactFinger, held_finger
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, TetMesh
from flexsheet.fem.path_snapshots import PathSnapshotModel, check_path_table, path_table_key
from flexsheet.fem.realtime import CondensedSurface, Update, dist_to_points
from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC, scene_mesh
from flexsheet.fem.solver import CapacitanceSolver, FemModel
from flexsheet.fem.sphere_snapshots import SphereSnapshotModel, sphere_frame, sphere_table_key
from flexsheet.model.scenes import Scene

log = logging.getLogger(__name__)

__all__ = ["SceneModel", "SurfaceIndex", "scene_finger", "finger_on_scene", "one_blas_thread", "STICKY_DEPTH",
           "STIFFNESS_FLOOR", "attach_scene_table", "scene_cache_key"]

_CACHE_VERSION = "scene-1"
#: a finger pressed at least this deep keeps its contact point and push direction, m
STICKY_DEPTH = 0.005
#: the stiffness of a lighter touch is that of a press this deep, m (the planner's ``min_contact_depth``)
STIFFNESS_FLOOR = 0.0005


def scene_cache_key(scene, spec: MeshSpec, order: int, finger_radius: float, reach: float) -> str:
    """The key of a scene's real-time model (:class:`SceneModel`'s precompute, and the key a path table is
    stored under with it): the scene (``Scene.key()``), mesh spec, gmsh's version, reach (m), finger radius
    (m), element order."""
    import gmsh

    return cache_key(_CACHE_VERSION, scene.key(), spec.key(), gmsh.__version__, f"{reach:.9g}",
                     f"{finger_radius:.9g}", f"P{order}")


class SurfaceIndex:
    """Dense samples of a scene's surface for fast closest-point queries: ``points`` (K, 3) m, outward unit
    ``normals`` (K, 3), display frame. Built from the scene's surface mesh (vertices + face centroids, the
    normals from :meth:`Scene.surface_point`)."""

    def __init__(self, scene):
        from scipy.spatial import cKDTree

        v, f = scene.surface_mesh()
        v = np.asarray(v, float)
        samples = np.vstack([v, v[np.asarray(f)].mean(axis=1)])
        self.points, self.normals = scene.surface_point(samples)
        self._tree = cKDTree(self.points)

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(contact point (3,) m, outward normal (3,), signed distance m (< 0 inside)) of point ``x`` (3,):
        ``x`` projected onto the tangent plane at its nearest sample."""
        _, i = self._tree.query(x)
        n = self.normals[i]
        s = float((x - self.points[i]) @ n)
        return x - s * n, n, s


def scene_finger(tip, surface: SurfaceIndex, radius: float, max_depth: float, fixed_mask=None,
                 anchor: ContactFinger | None = None, sticky_depth: float = STICKY_DEPTH) -> ContactFinger:
    """Finger geometry (:class:`flexsheet.fem.contact.ContactFinger`) from the measured fingertip ``tip`` (3,)
    m on a scene's surface (module doc). ``fixed_mask`` optional callable(points (1, 3)) → (1,) bool: a
    contact point the support holds is refused. Raises ``ValueError`` naming ``tip`` when it is not a finite
    (3,) vector, deeper than ``max_depth`` m, or its contact point lies on the support. A tip outside the
    object gives depth 0 (no contact)."""
    p = np.asarray(tip, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"tip must be a finite (3,) position in m, got {tip!r}")
    if anchor is not None and anchor.depth >= sticky_depth:       # scene fingers carry azimuth/axial 0
        return held_finger(p, anchor, radius, max_depth)
    cp, n, s = surface.project(p)
    depth = -s
    if depth > max_depth:
        raise ValueError(f"tip {p.tolist()} is {depth * 1e3:.1f} mm deep, beyond max_depth "
                         f"{max_depth * 1e3:.1f} mm")
    if depth > 0 and fixed_mask is not None and bool(np.asarray(fixed_mask(cp[None]))[0]):
        raise ValueError(f"tip {p.tolist()} presses on the object's support (held surface) at "
                         f"{np.round(cp, 4).tolist()}")
    return ContactFinger(p + radius * n, -n, float(radius), max(0.0, depth), cp, 0.0, 0.0)


def finger_on_scene(point, normal, depth: float, radius: float) -> ContactFinger:
    """A finger pushed ``depth`` m (≥ 0) along −``normal`` at the surface ``point`` (3,) m (outward unit
    ``normal`` (3,)); for experiments and tests. Raises ``ValueError`` for a negative or non-finite depth or
    radius ≤ 0."""
    if not (math.isfinite(depth) and depth >= 0.0):
        raise ValueError(f"depth must be >= 0 m, got {depth!r}")
    if not (math.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius must be > 0 m, got {radius!r}")
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    q = np.asarray(point, float)
    tip = q - depth * n
    return ContactFinger(tip + radius * n, -n, float(radius), float(depth), q.copy(), 0.0, 0.0)


_BLAS = None


class _OneThread:
    """Set every BLAS library threadpoolctl found to one thread on entry and restore their counts on exit
    (what ``ThreadpoolController.limit(limits=1, user_api="blas")`` does, without rebuilding the libraries'
    info dicts on every call: ~2 µs instead of ~10 µs per update)."""

    def __init__(self, libs):
        self._libs = libs

    def __enter__(self):
        self._saved = [lib.get_num_threads() for lib in self._libs]
        for lib in self._libs:
            lib.set_num_threads(1)
        return self

    def __exit__(self, *exc):
        for lib, n in zip(self._libs, self._saved, strict=True):
            lib.set_num_threads(n)
        return False


def one_blas_thread():
    """Context manager: BLAS/LAPACK limited to one thread (threadpoolctl) — the update's dense Cholesky of
    a few hundred rows. OpenBLAS's default threads spin against each other on a busy 2-core machine: a
    189 × 189 ``cho_factor`` measured 240 ms with 2 threads and 0.09 ms with 1 (load average ~10). A no-op
    when threadpoolctl is not installed."""
    global _BLAS
    if _BLAS is None:
        try:
            from threadpoolctl import ThreadpoolController

            _BLAS = _OneThread([lib for lib in ThreadpoolController().lib_controllers
                                if lib.user_api == "blas"])
        except ImportError:           # pragma: no cover - optional dependency
            _BLAS = False
    if _BLAS is False:
        import contextlib

        return contextlib.nullcontext()
    return _OneThread(_BLAS._libs)


class SceneModel(CondensedSurface):
    """Real-time linear model of ``scene`` (a :class:`flexsheet.model.scenes.Scene`; module doc).

    Parameters: ``spec`` mesh sizes (default :data:`flexsheet.fem.scene_mesh.DEFAULT_SCENE_SPEC`); ``order``
    element order (2: P2, whose edge midpoints take contact too); ``finger_radius`` m (None: the scene's);
    ``max_depth`` m (deeper input is rejected); ``strain_limit``; ``cache_dir`` (None: no disk cache);
    ``reach`` m: candidate contact points lie within this distance of the stroke path (default finger
    radius + 4 mm). Precompute (mesh, assembly, 3·#candidates sparse solves)
    is cached by :class:`flexsheet.fem.cache.ArrayCache` under a key of ``scene.key()``, the spec, gmsh's
    version, finger radius, reach and order. ``precompute_s``, ``cache_hit``, ``scene_key`` tell how start-up
    went and what is solved. Raises ``ValueError`` on bad parameters.
    """

    def __init__(self, scene, spec: MeshSpec = DEFAULT_SCENE_SPEC, order: int = 2,
                 finger_radius: float | None = None,
                 max_depth: float = 0.06, strain_limit: float = 1.0,
                 cache_dir: str | None = DEFAULT_CACHE_DIR,
                 reach: float | None = None):
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a flexsheet.model.scenes.Scene, got {type(scene).__name__}")
        finger_radius = scene.finger.radius if finger_radius is None else finger_radius
        self._check_params(finger_radius, max_depth, strain_limit)
        if order not in (1, 2):
            raise ValueError(f"order must be 1 or 2, got {order!r}")
        reach = finger_radius + 0.004 if reach is None else float(reach)
        if not (math.isfinite(reach) and 0.0 < reach <= 0.05):
            raise ValueError(f"reach must be in (0, 0.05] m, got {reach!r}")

        t0 = time.perf_counter()
        self.scene, self.spec, self.order = scene, spec, order
        self.scene_key = scene.key()
        self.material = Material(scene.material.E, scene.material.nu)
        self.finger_radius, self.max_depth, self.strain_limit, self.reach = (finger_radius, max_depth,
                                                                             strain_limit, reach)
        self.cache_key = scene_cache_key(scene, spec, order, finger_radius, reach)
        self.cache = ArrayCache(cache_dir)
        self._model = None
        z, self.cache_hit, _ = self.cache.get_or_compute("scenecap", self.cache_key, self._precompute,
                                                         f"capacitance matrices of scene {scene.name!r}")
        try:
            self.mesh = TetMesh(z["points"], z["tets"], z["faces"], z["fixed"], spec,
                                center=np.asarray(scene.center, float).copy())
            self.E_elem, self.nu_elem = np.asarray(z["E"]), np.asarray(z["nu"])
            # single precision per update: displacements within 0.05
            # µm of float64 (tests/unit/fem/test_scene_model.py)
            self.solver = CapacitanceSolver.from_arrays(z, dtype=np.float32)
            monitor = z["monitor"]
        except (KeyError, ValueError) as exc:
            raise ValueError(f"scene capacitance cache entry {self.cache_key} is inconsistent: "
                             f"{exc}") from exc
        self._set_output_maps(monitor)
        #: (S,) bool: the rendered vertices the scene's support holds (exactly at rest in every served push)
        self.held = np.asarray(self.mesh.fixed[self.surface_nodes], bool)
        self.surface = SurfaceIndex(scene)
        self._anchor: ContactFinger | None = None
        self.snapshots = None
        #: the nonlinear path table (:meth:`attach_path_table`), or None
        self.path_table = None
        self.precompute_s = time.perf_counter() - t0

    def attach_sphere_snapshots(self, table: dict) -> None:
        """Serve pushes inside a sphere scene's nonlinear table (:mod:`flexsheet.fem.sphere_snapshots`) from
        it, the linear model elsewhere. Raises ``ValueError`` when the table is inconsistent or was built for
        another sphere (centre or radius). Thread-safe to call while updates run (one assignment)."""
        fr = sphere_frame(self.scene)
        sm = SphereSnapshotModel(table, self._rest.astype(np.float64), E=self.material.E)
        if np.linalg.norm(sm.frame.center - fr.center) > 1e-9 or abs(sm.frame.radius - fr.radius) > 1e-9:
            raise ValueError(f"sphere table is for centre {sm.frame.center.tolist()} radius "
                             f"{sm.frame.radius:g} m, the scene's sphere is at {fr.center.tolist()} radius "
                             f"{fr.radius:g} m")
        self.snapshots = sm

    def attach_path_table(self, table: dict) -> None:
        """Serve pushes along the stroke from a path table (:mod:`flexsheet.fem.path_snapshots`: the stations'
        solved states, each moved with the contact and blended along the stroke and in depth; the force the
        linear solve's times the table's ratio), the linear model elsewhere. Raises ``ValueError`` when the
        table is inconsistent or was built on another real-time mesh. Solves each station's push at each table
        depth with this model (the states are these solves plus the table's correction) and precomputes the
        contact moves (about 1 s for the shipped tables); then thread-safe to call while updates run (one
        assignment)."""
        n_path = max(2, int(math.ceil(self.scene.stroke_length() / 0.0002)) + 1)    # 0.2 mm apart
        pf = np.linspace(0.0, 1.0, n_path)
        path, path_n = self.scene.stroke_at(pf)
        check_path_table(table)
        depths = np.asarray(table["depths"], float)
        linear = np.zeros(np.shape(table["correction"]))
        if linear.shape[2] == len(self._rest):      # else PathSnapshotModel refuses the table (another mesh)
            with one_blas_thread():                  # beside the update thread on a small machine
                for k, (q, n) in enumerate(zip(np.asarray(table["points"], float),
                                               np.asarray(table["normals"], float), strict=True)):
                    for j in range(1, len(depths)):
                        linear[k, j] = self.surface_displacement(finger_on_scene(q, n, float(depths[j]),
                                                                                 self.finger_radius))[0]
        pt = PathSnapshotModel(table, self._rest.astype(np.float64), self.faces, path, path_n, pf, linear)
        self.path_table = pt

    # ------------------------------------------------------------------ precompute
    def _build_model(self, mesh: TetMesh, E: np.ndarray, nu: np.ndarray) -> FemModel:
        return FemModel(mesh, self.material, order=self.order, support=self.scene.fixed_mask, E_elem=E,
                        nu_elem=nu)

    def _precompute(self) -> dict:
        sm = scene_mesh(self.scene, self.spec)
        m = sm.mesh
        log.info(f"fem: scene {self.scene.name!r}: {len(m.points)}-node mesh ({sm.how}), "
                  f"{int(np.count_nonzero(sm.E != self.material.E))} inclusion elements")
        model = self._build_model(m, sm.E, sm.nu)
        n_path = max(2, int(math.ceil(self.scene.stroke_length() / 0.001)) + 1)
        path, _ = self.scene.stroke_points(n_path)
        dist = dist_to_points(model.points, path)
        surf = model.boundary & ~model.fixed
        candidates = surf & (dist <= self.reach)
        if not candidates.any():
            raise ValueError(f"scene {self.scene.name!r}: no free surface node within reach "
                             f"{self.reach * 1e3:.1f} mm "
                             "of the stroke path (is the stroke on the support?)")
        monitor = (dist <= self.reach + 2 * self.spec.h_fine)[:len(m.points)]
        corner = np.arange(len(model.points)) < len(m.points)
        outputs = (surf | (np.pad(monitor, (0, len(model.points) - len(m.points))) & ~model.fixed)) & corner
        log.info(f"fem: scene {self.scene.name!r}: precomputing capacitance matrices for "
                  f"{int(candidates.sum())} candidate contact points on a {len(m.points)}-node P{self.order} "
                  "mesh ...")
        solver = CapacitanceSolver(model, candidates, outputs)
        self._model = model
        return {"points": m.points, "tets": m.tets, "faces": m.faces, "fixed": m.fixed, "monitor": monitor,
                "E": sm.E, "nu": sm.nu, **solver.arrays()}

    @property
    def model(self) -> FemModel:
        """The assembled FEM model (built on first use after a cache hit: the sparse fallback needs it)."""
        if self._model is None:
            self._model = self._build_model(self.mesh, self.E_elem, self.nu_elem)
        return self._model

    # ------------------------------------------------------------------ updates
    def finger(self, tip) -> ContactFinger:
        """The :class:`ContactFinger` for fingertip ``tip`` (3,) m without changing the held contact (see
        :func:`scene_finger`). Raises ``ValueError``."""
        return scene_finger(tip, self.surface, self.finger_radius, self.max_depth, self.scene.fixed_mask,
                            anchor=self._anchor)

    def update(self, tip) -> Update:
        """Deform the object for fingertip ``tip`` (3,) m display frame. Stateful: a finger pressed ≥ 5 mm
        keeps its contact point. Raises ``ValueError`` for NaN/inf, too-deep or on-the-support input.
        Never returns non-finite vertices (``valid=False`` with the rest shape instead)."""
        fg = self.finger(tip)
        self._anchor = fg if fg.depth > 0 else None
        return self.update_finger(fg)

    def reset(self) -> None:
        """Forget the held contact point."""
        self._anchor = None

    def update_finger(self, fg: ContactFinger) -> Update:
        """As :meth:`update` for a prepared :class:`ContactFinger`: the capacitance solve, or the full sparse
        solve when the finger touches surface outside the precomputed region (``method = "sparse"``); BLAS on
        one thread (:func:`one_blas_thread`)."""
        with one_blas_thread():
            return self._update_finger(fg)

    def _update_finger(self, fg: ContactFinger) -> Update:
        snap = self.snapshots
        if snap is not None and fg.depth > 0:
            n, d = snap.radial_push(fg.contact_point + fg.depth * fg.direction)
            if snap.covers(n, d):
                return self._update_snapshots(snap, fg, n, d)
        pt = self.path_table
        if pt is not None and fg.depth > 0:
            f, lateral = pt.locate(fg.contact_point)
            if pt.covers(f, lateral, fg.depth):
                return self._update_path(pt, fg, f, lateral)
        sol, u_out, method = self._solve(fg)
        stiffness = self._floored_stiffness(fg, sol)
        strain, inv = self._checks(fg, u_out) if sol.n_contact else (0.0, 0)
        us = self._surface_of(u_out)
        finite = bool(np.all(np.isfinite(us))) and math.isfinite(sol.force) and math.isfinite(stiffness)
        status, valid = "ok", True
        if not finite:
            status, valid = "linear_invalid:non_finite", False
        elif inv > 0 or strain > self.strain_limit:
            status = "linear_invalid:" + (f"inverted={inv}" if inv > 0
                                          else f"strain={strain:.2f}>{self.strain_limit:g}")
        if valid:
            folded = self.folded_faces(us)
            if folded:
                status, valid = f"linear_invalid:folded_surface={folded}", False
        verts = self._rest + (us.astype(np.float32) if valid else 0.0)
        return Update(verts.astype(np.float32), float(sol.force) if valid else 0.0,
                      float(stiffness) if valid else 0.0, fg.depth, fg.contact_point.copy(), method,
                      float(strain), int(inv), status, valid)

    def _update_snapshots(self, snap, fg: ContactFinger, normal: np.ndarray, depth: float) -> Update:
        """The sphere table's answer (method "snapshots") for the radial push (``normal``, ``depth``) through
        the finger's leading point: its surface, force and dF/dd; the strain and inverted elements are the
        reference's at the bracketing snapshots."""
        us, force, stiff, strain, inv = snap.surface(normal, depth)
        us[self.held] = 0.0        # the look-up rotates the field; the held back half stays where it is
        if not (np.all(np.isfinite(us)) and math.isfinite(force) and math.isfinite(stiff)):
            return Update(self._rest.copy(), 0.0, 0.0, fg.depth, fg.contact_point.copy(), "snapshots", 0.0, 0,
                          "nonlinear_invalid:non_finite", False)
        status = "ok" if inv == 0 else f"nonlinear_invalid:inverted={inv}"
        return Update((self._rest + us.astype(np.float32)).astype(np.float32), force, stiff, fg.depth,
                      fg.contact_point.copy(), "snapshots", strain, inv, status, True)

    def _floored_stiffness(self, fg: ContactFinger, sol) -> float:
        """The linear solve ``sol``'s dF/dd, or for a touch lighter than :data:`STIFFNESS_FLOOR` that of a
        press that deep at the same point (one more capacitance solve; module doc)."""
        if 0.0 < fg.depth < STIFFNESS_FLOOR:
            press = finger_on_scene(fg.contact_point, -fg.direction, STIFFNESS_FLOOR, fg.radius)
            return self._solve(press, outputs=False)[0].stiffness
        return sol.stiffness

    def _update_path(self, pt, fg: ContactFinger, fraction: float, lateral: float) -> Update:
        """The path table's answer (method "path_snapshots"): the table's blended states at (``fraction``,
        depth), faded to the linear solve's surface as the contact's ``lateral`` offset (m) from the stroke
        goes from half the table's reach to its reach (continuous at the table's side); no vertex inside the
        fingertip; force and dF/dd the linear solve of this push times the table's ratios; the strain and
        inverted elements are the reference's at the bracketing samples. No fold test (as the sphere's table):
        the reference's own surface, sampled on the rendered triangles, folds around the fingertip (rounded
        box, 50 mm: up to 102 of them at a station, all under or beside the finger), and the test exists to
        catch the *linear* model's overlapping surface; non-finite values give ``valid`` False."""
        w = min(1.0, max(0.0, (pt.reach - lateral) / (0.5 * pt.reach)))   # the states' weight
        # force and dF/dd; its surface only where it fades in
        sol, u_out, _ = self._solve(fg, outputs=w < 1.0)
        stiffness = self._floored_stiffness(fg, sol)
        us, rf, rk, strain, inv = pt.lookup(fraction, fg.depth)
        if w < 1.0:
            us = np.float32(w) * us + np.float32(1.0 - w) * self._surface_of(u_out).astype(np.float32)
        us = self._outside_finger(us, fg)
        us[self.held] = 0.0
        force, stiffness = float(sol.force) * rf, float(stiffness) * rk
        status, valid = ("ok" if inv == 0 else f"nonlinear_invalid:inverted={inv}"), True
        if not (np.all(np.isfinite(us)) and math.isfinite(force) and math.isfinite(stiffness)):
            status, valid = "nonlinear_invalid:non_finite", False
        verts = self._rest + (us.astype(np.float32) if valid else 0.0)
        return Update(verts.astype(np.float32), force if valid else 0.0, stiffness if valid else 0.0,
                      fg.depth,
                      fg.contact_point.copy(), "path_snapshots", strain, inv, status, valid)

    def _outside_finger(self, us: np.ndarray, fg: ContactFinger) -> np.ndarray:
        """``us`` (S, 3) with every vertex that the blend left inside the fingertip sphere put on it, along
        the ray from its centre (the material under a rigid finger lies on it). A station's dent moved between
        stations loses depth to linear interpolation on the rendered triangles (h²/8r: 0.25 mm for 4 mm
        triangles under an 8 mm fingertip); this keeps the drawn dent on the finger. Continuous in the
        finger's position: a vertex reaching the sphere moves by nothing."""
        c = np.asarray(fg.center, np.float32)
        x = self._rest + us - c
        r2 = np.einsum("ij,ij->i", x, x)
        inside = np.flatnonzero(r2 < np.float32(fg.radius) ** 2)
        if len(inside):
            d = np.sqrt(np.maximum(r2[inside], np.float32(1e-24)))
            us[inside] += x[inside] * (np.float32(fg.radius) / d - 1.0)[:, None]
        return us

    def surface_displacement(self, fg: ContactFinger) -> tuple[np.ndarray, float, float]:
        """(surface-node displacements (S, 3) m, force N, stiffness N/m) of one push, no checks
        (experiments)."""
        sol, u_out, _ = self._solve(fg)
        return self._surface_of(u_out), float(sol.force), float(sol.stiffness)



def attach_scene_table(model: SceneModel, cache: ArrayCache) -> tuple[str | None, str | None]:
    """Attach the scene's nonlinear table to ``model`` as the FEM node serves it: a sphere scene's sphere
    table (:mod:`flexsheet.fem.sphere_snapshots`), any other scene's path table
    (:mod:`flexsheet.fem.path_snapshots`), from ``cache`` (this machine's cache, then the shipped store
    ``flexsheet/fem/data``). Returns (kind "sphere" or "path",
    where: "cache" or "shipped store (flexsheet/fem/data)"), or (kind, None) when none is stored (the model
    stays linear). Raises ``ValueError`` when a stored table is unusable (inconsistent, another mesh)."""
    try:
        sphere_frame(model.scene)
        kind, table = "sphere", cache.load("spheresnap", sphere_table_key(model.scene))
    except ValueError:
        kind, table = "path", cache.load("pathsnap", path_table_key(model.scene_key, model.cache_key))
    if table is None:
        return kind, None
    if kind == "sphere":
        model.attach_sphere_snapshots(table)
    else:
        model.attach_path_table(table)
    return kind, ("shipped store (flexsheet/fem/data)" if cache.shipped() else "cache")
