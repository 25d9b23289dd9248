"""The cylinder's cached hyperelastic reference pushes: :func:`reference_path` (the loading path) and
:func:`stable_path` (its stable branch where a push is bistable), their cache keys (:func:`reference_key`,
:func:`stable_key`), the per-depth arrays cached, and their states for a snapshot table (:func:`path_states`,
:func:`snapshot_table`). Progress goes to this module's logger at INFO (shown by the command line and,
prefixed, in the worker processes of :mod:`flexsheet.fem.reference.workers`:
:func:`flexsheet.runtime.console.show_lines`)."""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT, PENALTY_SCALE, capsule_at
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.mesh import RefSpec, reference_mesh
from flexsheet.fem.reference.path_solver import PathState, solve_path, stable_states
from flexsheet.fem.reference.settings import FINGER_R, NEWTON_ITERS, Settings
from flexsheet.fem.reference.snapshot_build import folded_probe, load_or_build, unfolded_sample
from flexsheet.fem.reference.versions import UNLOAD_VERSION, solver_tag

log = logging.getLogger(__name__)


def reference_model(spec: RefSpec, angle_deg: float, mat: Material, penalty_scale: float = PENALTY_SCALE
                    ) -> HyperelasticModel:
    """The hyperelastic model :func:`reference_path` solves for ``spec`` at ``angle_deg`` (deg) with ``mat``:
    the quarter model at azimuth 0 when ``spec.half_z``, else the half model; contact penalty
    ``penalty_scale``·E/h."""
    half_z = spec.half_z and angle_deg == 0.0
    mesh = reference_mesh(replace(spec, half_z=half_z), angle_deg)
    return HyperelasticModel(mesh, mat, sym_y=True, sym_z=half_z, penalty_scale=penalty_scale)


def load_step(depths: np.ndarray) -> float:
    """Load step (m) of a :func:`reference_path` through ``depths`` m: their spacing, at most 2.5 mm."""
    return float(min(0.0025, np.min(np.diff(np.concatenate([[0.0], depths])))))


def reference_key(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, probes: np.ndarray,
                  contact: str, penalty_scale: float) -> str:
    """Cache key of the :func:`reference_path` that solves ``spec`` at ``angle_deg`` (:func:`as_solved`
    applied: the half model off azimuth 0): everything the path depends on."""
    spec, angle_deg = as_solved(spec, angle_deg)
    return cache_key(solver_tag(contact), spec.key(), angle_deg, np.round(depths, 9).tolist(), mat.key(),
                     FINGER_R, cache_key(np.round(probes, 9).tobytes()), f"step={load_step(depths):.6g}",
                     f"iters={NEWTON_ITERS}", f"pen={penalty_scale:g}")


def check_dofs(path: dict, model: HyperelasticModel) -> None:
    """Raise ``RuntimeError`` when the cached reference ``path`` (with its ``dofs``) has another DOF count
    than ``model``, the mesh re-made to read it (the cache key does not carry gmsh's version: a new gmsh may
    mesh differently)."""
    if "dofs" in path and int(path["dofs"]) != model.n:
        raise RuntimeError(f"the cached reference path has {int(path['dofs'])} DOF, the re-meshed model "
                           f"{model.n}: "
                           "gmsh meshes differently now; clear the fem cache (~/.cache/flexsheet/fem) and "
                           "re-solve")


def as_solved(spec: RefSpec, angle_deg: float) -> tuple[RefSpec, float]:
    """(spec, azimuth) as :func:`reference_path` solves and keys them: -0.0 → 0.0, and the half model
    (``half_z`` off) away from azimuth 0."""
    angle_deg = float(angle_deg) + 0.0
    return (replace(spec, half_z=False) if angle_deg != 0.0 and spec.half_z else spec), angle_deg


def _path_record(model: HyperelasticModel, states: list[PathState], probes: np.ndarray,
                 angle_deg: float) -> dict:
    """The per-depth arrays :func:`reference_path` caches for ``states`` on ``model`` (see there), ``probes``
    (k, 3) m the rendered vertices."""
    P = folded_probe(model, probes)
    qp, vis = [], []
    a = math.radians(angle_deg)
    axis = np.array([math.cos(a), 0.0, math.sin(a)])
    for s in states:
        qp.append(int(np.count_nonzero(np.linalg.det(model.deformation(s.u)).min(axis=1) <= 0)))
        ue = s.u[model.edofs]
        bad = np.flatnonzero(np.linalg.det(model.nodal_deformation(s.u)).min(axis=1) <= 0)
        xc = (model.points[model.edofs[bad]] + ue[bad]).mean(axis=1) - model.mesh.center
        lat = np.linalg.norm(xc - np.outer(xc @ axis, axis), axis=1)
        vis.append(int(np.count_nonzero(lat > FINGER_R + 0.002)))
    return {"u": np.stack([unfolded_sample(P, s.u, probes, model) for s in states]),
            "u_dof": np.stack([s.u for s in states]).astype(np.float32),
            "force": np.array([s.force for s in states]), "inverted": np.array([s.inverted for s in states]),
            "inverted_qp": np.array(qp), "inverted_nodal_visible": np.array(vis),
            "min_detF": np.array([s.min_detF for s in states]),
            "max_strain": np.array([s.max_strain for s in states]),
            "penetration": np.array([s.penetration for s in states]),
            "newton": np.array([s.iterations for s in states]),
            "converged": np.array([s.converged for s in states])}


def reference_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                   probes: np.ndarray, contact: str = DEFAULT_CONTACT,
                   penalty_scale: float = PENALTY_SCALE) -> dict:
    """Hyperelastic (``mat``: neo-Hookean or Gent) push at ``angle_deg`` through ``depths`` (load steps = the
    depth spacing, ≤ 2.5 mm) on ``spec``'s mesh — its half model (``half_z`` off) away from azimuth 0, as
    :func:`flexsheet.fem.reference.snapshot_build.build_table` meshes it, so one solve serves both — sampled
    at ``probes`` (k, 3) m (display frame, mirrored into the modelled part); cached. Returns {"u": (D, k, 3)
    m, "u_dof": (D, P, 3) m float32 (every DOF point, for the snapshot table), "force", "inverted" (elements
    with det F ≤ 0 at a quadrature point or P2 node), "inverted_qp" (at a quadrature point),
    "inverted_nodal_visible" (nodally inverted elements whose deformed centroid lies outside the footprint, >
    finger radius + 2 mm from the push axis), "min_detF", "max_strain", "penetration", "newton", "seconds",
    "cpu_seconds", "dofs", "converged"}. ``contact``: the finger's contact law
    (:data:`flexsheet.fem.reference.capsule_contact.CONTACT_LAWS`); ``penalty_scale``: the contact penalty κ =
    scale·E/h."""
    spec, angle_deg = as_solved(spec, angle_deg)
    step = load_step(depths)
    key = reference_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale)

    def compute() -> dict:
        t, tc = time.perf_counter(), time.process_time()
        model = reference_model(spec, angle_deg, mat, penalty_scale)
        log.info(f"reference {spec.key()} at {angle_deg:g} deg: {model.n} DOF, load steps {step * 1e3:g} mm, "
                 f"{contact} contact, penalty {penalty_scale:g} E/h ...")
        states = solve_path(model, math.radians(angle_deg), depths, FINGER_R, step=step, iters=NEWTON_ITERS,
                            contact=contact)
        return {**_path_record(model, states, probes, angle_deg),
                "seconds": np.array(time.perf_counter() - t),
                "cpu_seconds": np.array(time.process_time() - tc),
                "dofs": np.array(model.n)}

    z, hit, _ = cache.get_or_compute("reference", key, compute,
                                     f"reference {spec.key()} at {angle_deg:g} deg, penalty "
                                     f"{penalty_scale:g} E/h")
    return z


def stable_key(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, probes: np.ndarray,
               contact: str, penalty_scale: float) -> str:
    """Cache key of a :func:`stable_path`: its loading path's key and the unloading sweep's version."""
    return cache_key(UNLOAD_VERSION,
                     reference_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale))


def stable_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                probes: np.ndarray, contact: str = DEFAULT_CONTACT,
                penalty_scale: float = PENALTY_SCALE) -> dict:
    """:func:`reference_path` with the stable branch where the push is bistable: the loading path, then the
    finger withdrawn from its deepest state back to the shallowest
    (:func:`flexsheet.fem.reference.path_solver.stable_states`, the path's load steps), and at each depth the
    state of lower total potential Π. The snapshot tables and the held-out pushes they are judged on read
    these, so both sides make the same choice. Cached (kind "stable", read before the loading path is);
    frictionless contact only (else the loading path itself). Returns :func:`reference_path`'s dict plus
    "branch" (D,) int (1: the unloaded state), "energy_loading", "energy_unloading" (D,) J (Π of each branch's
    state), "unload_seconds"."""
    if contact != "frictionless":
        return reference_path(spec, angle_deg, depths, mat, cache, probes, contact, penalty_scale)
    spec, angle_deg = as_solved(spec, angle_deg)
    key = stable_key(spec, angle_deg, depths, mat, probes, contact, penalty_scale)

    def compute() -> dict:
        p = reference_path(spec, angle_deg, depths, mat, cache, probes, contact, penalty_scale)
        t = time.perf_counter()
        model = reference_model(spec, angle_deg, mat, penalty_scale)
        check_dofs(p, model)
        states = path_states(p, depths, depths)
        a = math.radians(angle_deg)
        caps = lambda d: capsule_at(a, d, FINGER_R, model.mesh.radius, model.mesh.center)  # noqa: E731
        log.info(f"stable branch {spec.key()} at {angle_deg:g} deg: unloading from {depths[-1] * 1e3:g} mm "
                 "...")
        chosen, branch, energies = stable_states(model, caps, states, step=load_step(depths),
                                                 iters=NEWTON_ITERS)
        return {**_merge_rows(p, branch, lambda rows: _path_record(model, [chosen[j] for j in rows], probes,
                                                                    angle_deg)),
                "branch": branch, "energy_loading": energies[:, 0], "energy_unloading": energies[:, 1],
                "unload_seconds": np.array(time.perf_counter() - t)}

    z, _, _ = cache.get_or_compute("stable", key, compute, f"stable branch {spec.key()} at {angle_deg:g} deg")
    n_un = int(np.sum(z["branch"]))
    log.info(f"stable branch {spec.key()} at {angle_deg:g} deg: the unloaded state at {n_un} of "
             f"{len(depths)} depths"
             + (f" ({', '.join(f'{d * 1e3:g}' for d in depths[np.asarray(z['branch']) == 1])} mm)" if n_un
                else ""))
    return z


def _merge_rows(p: dict, branch: np.ndarray, record) -> dict:
    """``p`` (a :func:`reference_path` dict, per-depth arrays of length D) with the rows where ``branch`` (D,)
    is 1 replaced by ``record(rows)`` (a :func:`_path_record` of those rows' states), each array's dtype
    kept."""
    rows = np.flatnonzero(branch)
    out = dict(p)
    if len(rows) == 0:
        return out
    for k_, v in record(rows).items():
        arr = np.array(p[k_], copy=True)
        arr[rows] = v.astype(arr.dtype)
        out[k_] = arr
    return out


def push_depths(step: float) -> np.ndarray:
    """Push depths step, 2·step, … 50 mm (m)."""
    return np.round(np.arange(1, int(round(0.05 / step)) + 1) * step, 9)


def at_depths(path: dict, path_depths: np.ndarray, depths: np.ndarray) -> dict:
    """``path`` (a :func:`reference_path` result sampled at ``path_depths``, m) with its per-depth arrays
    taken at the nearest of ``depths`` (m)."""
    sub = np.array([int(np.argmin(np.abs(path_depths - d))) for d in depths])
    return {k: (v[sub] if np.ndim(v) and len(v) == len(path_depths) else v) for k, v in path.items()}


def path_states(src: dict, src_depths: np.ndarray, depths, model=None) -> list[PathState] | None:
    """The states of the cached reference path ``src`` (:func:`reference_path`, solved at ``src_depths`` (D,)
    m) at ``depths`` m, as :class:`PathState` for :func:`flexsheet.fem.reference.snapshot_build.build_table`;
    None if one is missing. Raises ``RuntimeError`` when ``model`` (the mesh the table samples) has another
    DOF count than the solve (the cache key does not carry gmsh's version: a new gmsh may mesh
    differently)."""
    if model is not None:
        check_dofs(src, model)
    out = []
    for d in depths:
        j = int(np.argmin(np.abs(src_depths - d)))
        if abs(src_depths[j] - d) > 1e-9:
            return None
        out.append(PathState(float(d), src["u_dof"][j].astype(float), float(src["force"][j]), np.zeros(3),
                             int(src["newton"][j]), bool(src["converged"][j]), float(src["min_detF"][j]),
                             int(src["inverted"][j]), float(src["max_strain"][j]),
                             float(src["penetration"][j]), 0))
    return out


def cached_path(spec: RefSpec, angle_deg: float, depths: np.ndarray, mat: Material, cache: ArrayCache,
                 probes: np.ndarray, contact: str = DEFAULT_CONTACT) -> dict | None:
    """:func:`stable_path` (frictionless; else :func:`reference_path`) when it is in ``cache``, else None —
    never solved here."""
    if contact == "frictionless":
        return cache.load("stable", stable_key(spec, angle_deg, depths, mat, probes, contact, PENALTY_SCALE))
    return cache.load("reference",
                      reference_key(spec, angle_deg, depths, mat, probes, contact, PENALTY_SCALE))


def snapshot_table(st: Settings, mat: Material, cache: ArrayCache, solved,
                   reuse: dict | None = None) -> tuple[dict, bool, float]:
    """The snapshot table of these settings (cached): (table, cache hit, seconds to build). ``solved``:
    callable (azimuth deg, model, depths m) → states or None
    (:func:`flexsheet.fem.reference.snapshot_build.build_table`), the reference solves already made
    (:func:`snapshot_source`, :func:`node_table_path`); ``reuse``: a table whose azimuths are copied, not
    solved (:func:`flexsheet.fem.reference.snapshot_build.build_table`)."""
    log.info(f"snapshots: azimuths {st.grid.angles_deg} deg, depth step {st.grid.depth_step * 1e3:g} mm, "
             f"mesh {st.snap_spec.key()} ...")

    table, hit, sec = load_or_build(cache, st.grid, st.snap_spec, mat, FINGER_R, build=True, solved=solved,
                                    contact=st.contact,
                                    reuse=reuse)
    if hit:
        sec = float(np.sum(table["seconds"]))
    return table, hit, sec
