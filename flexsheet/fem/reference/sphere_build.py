"""The offline build of the sphere scene's nonlinear table (:mod:`flexsheet.fem.sphere_snapshots` is its
run-time look-up and describes the table): one snapshot angle's push of the scene's hyperelastic body, its
stable branch and its samples on the table's grid (:func:`solve_alpha`), and the table's arrays from every
angle's result (:func:`assemble_table`). :mod:`flexsheet.fem.reference.sphere_table` runs them. Heavy: ~10 min
of one core per angle."""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.reference.capsule_contact import Capsule
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.path_solver import solve_path_capsule, stable_states
from flexsheet.fem.scene_mesh import scene_mesh
from flexsheet.fem.sphere_snapshots import (
    DEFAULT_SPHERE_GRID,
    DEFAULT_SPHERE_SPEC,
    SPHERE_TABLE_VERSION,
    SphereFrame,
    SphereGrid,
    grid_points,
    sphere_frame,
)

log = logging.getLogger(__name__)

__all__ = ["solve_alpha", "assemble_table"]


def solve_alpha(scene, alpha_deg: float, grid: SphereGrid = DEFAULT_SPHERE_GRID, spec=DEFAULT_SPHERE_SPEC,
                probes: np.ndarray | None = None, iters: int = 60) -> dict:
    """One snapshot angle: the scene's hyperelastic body pushed at polar angle ``alpha_deg`` (stroke plane)
    through the grid's depths on a mesh refined along that push path (``spec`` = (h, h_fine, refine_radius,
    path_depth) m), the loading path then its stable branch, sampled on the grid (and at ``probes`` (k, 3) m,
    e.g. the real-time model's rendered vertices), under the scene's contact law (a frictionless push keeps
    its stable branch, :func:`stable_states`; a sticking one its loading path). Heavy (~10 min of one core at
    h_fine 4.5 mm): cache it. Returns {"field": (D, T, P, 3) float32 m, "u_probes": (D, k, 3) float32, "force"
    (D,) N, "converged", "inverted", "max_strain", "min_detF", "newton", "branch" (D,), "dofs", "cpu_seconds",
    "unload_seconds"}; row 0 is the rest state."""
    fr = sphere_frame(scene)
    if not (math.isfinite(alpha_deg) and 0 <= alpha_deg < 90):
        raise ValueError(f"alpha_deg must be in [0, 90), got {alpha_deg!r}")
    h, h_fine, rr, path = spec
    n = fr.direction(math.radians(alpha_deg))
    q = fr.center + fr.radius * n
    steps = np.arange(0.0, path + 1e-12, rr / 3)
    t0, c0 = time.perf_counter(), time.process_time()
    sm = scene_mesh(scene, MeshSpec(h, h_fine, rr), refine_at=q[None] - steps[:, None] * n[None])
    mat = Material.of_scene(scene.material)
    m0 = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False, E_elem=sm.E, nu_elem=sm.nu)
    model = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False, support=m0.dof_points(sm.mesh.fixed),
                              E_elem=sm.E, nu_elem=sm.nu)
    r = scene.finger.radius
    depths = grid.depths()

    def caps(d):
        return Capsule(q - d * n + r * n, -n, r)

    log.info(f"sphere table: alpha {alpha_deg:g} deg: {model.n} DOF, {len(depths) - 1} depths ...")
    contact = scene.finger.contact
    states = solve_path_capsule(model, caps, depths[1:], step=grid.depth_step, iters=iters,
                                label=f"sphere {alpha_deg:g} deg", contact=contact)
    cpu = time.process_time() - c0
    t1 = time.perf_counter()
    if contact == "frictionless":     # a sticking push is monotone: its anchors depend on the loading history
        states, branch, _ = stable_states(model, caps, states, step=grid.depth_step, iters=iters)
    else:
        branch = np.zeros(len(states), np.int64)
    unload = time.perf_counter() - t1
    pts = grid_points(fr, grid)
    P = model.probe_matrix(pts)
    Pp = model.probe_matrix(np.asarray(probes, float)) if probes is not None else None
    nt, nph, nd = len(grid.thetas()), len(grid.phis()), len(depths)
    field = np.zeros((nd, nt, nph, 3), np.float32)
    up = np.zeros((nd, 0 if probes is None else len(probes), 3), np.float32)
    out = {k: np.zeros(nd) for k in ("force", "max_strain")}
    out["min_detF"] = np.ones(nd)
    out.update(converged=np.ones(nd, bool), inverted=np.zeros(nd, np.int64), newton=np.zeros(nd, np.int64))
    for j, s in enumerate(states, start=1):
        field[j] = np.asarray(P @ s.u).reshape(nt, nph, 3)
        if Pp is not None:
            up[j] = np.asarray(Pp @ s.u)
        out["force"][j], out["max_strain"][j], out["min_detF"][j] = s.force, s.max_strain, s.min_detF
        out["converged"][j], out["inverted"][j], out["newton"][j] = s.converged, s.inverted, s.iterations
    log.info(f"sphere table: alpha {alpha_deg:g} deg done in {time.perf_counter() - t0:.0f} s "
        f"(force at {depths[-1] * 1e3:g} mm {out['force'][-1]:.2f} N)")
    return {"field": field, "u_probes": up, **out, "branch": np.concatenate([[0], branch]).astype(np.int64),
            "dofs": np.array(model.n), "cpu_seconds": np.array(cpu), "unload_seconds": np.array(unload)}


def assemble_table(frame: SphereFrame, grid: SphereGrid, per_alpha: list[dict], E: float) -> dict:
    """The table arrays (:class:`flexsheet.fem.sphere_snapshots.SphereSnapshotModel`) from
    :func:`solve_alpha`'s results, one per grid angle in order; ``E`` Pa the modulus they were solved with.
    Raises ``ValueError`` on a count or shape mismatch."""
    if len(per_alpha) != len(grid.alphas_deg):
        raise ValueError(f"per_alpha: {len(per_alpha)} results for {len(grid.alphas_deg)} grid angles")
    field = np.stack([np.asarray(p["field"], np.float32) for p in per_alpha])
    shape = (len(grid.alphas_deg), len(grid.depths()), len(grid.thetas()), len(grid.phis()), 3)
    if field.shape != shape:
        raise ValueError(f"per_alpha fields {field.shape} do not match the grid {shape}")
    st = {k: np.stack([np.asarray(p[k]) for p in per_alpha]) for k in ("force", "max_strain", "inverted")}
    return {"version": np.array(SPHERE_TABLE_VERSION), "E": np.array(float(E)),
            "alphas": np.radians(np.asarray(grid.alphas_deg, float)), "depths": grid.depths(),
            "theta": grid.thetas(), "phi": grid.phis(), "field": field, **st,
            "center": frame.center, "radius": np.array(frame.radius), "axes": frame.axes}
