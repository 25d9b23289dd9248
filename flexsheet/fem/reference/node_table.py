"""The FEM node's shipped snapshot table of the cylinder, built from the cached reference pushes:
:func:`build_node_table` (solve what the cache lacks, assemble, ship into ``flexsheet/fem/data/``), one
azimuth's push (:func:`node_table_path`), and what ``node_table.json`` records of the table
(:func:`node_table_report`): the table judged at held-out azimuths (:func:`node_table_holdout`, against the
push's own solve and, ``twin``, the mesh's noise, :func:`twin_spec`), between its depths
(:func:`node_table_between_depths`) and its look-up time. ``flexsheet experiment fem --node-table`` runs it
(:mod:`flexsheet.experiments.fem`, which draws ``node_table.png``)."""

from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import replace

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.contact import finger_at
from flexsheet.fem.eye_judge import shape_px_by_depth
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import (
    cached_path,
    path_states,
    push_depths,
    snapshot_table,
    stable_path,
)
from flexsheet.fem.reference.settings import FINGER_R, Settings, law_name, settings_for
from flexsheet.fem.reference.snapshot_build import load_or_build, pack_table, reusable_table, reused_azimuths
from flexsheet.fem.reference.workers import Solve, prefetch
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, SnapshotModel, table_key
from flexsheet.fem.visible_error import realtime_model

log = logging.getLogger(__name__)


def check_azimuth(angle_deg: float) -> None:
    """``SystemExit`` unless ``angle_deg`` (deg) is one of DEFAULT_GRID's azimuths (the node table's)."""
    if float(angle_deg) not in DEFAULT_GRID.angles_deg:
        raise SystemExit(f"flexsheet experiment fem: --azimuth must be one of the node table's "
                         f"{[f'{a:g}' for a in DEFAULT_GRID.angles_deg]} deg, got {angle_deg:g}")


def node_table_path(angle_deg: float, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                    contact: str = DEFAULT_CONTACT) -> tuple[dict, np.ndarray]:
    """One azimuth of the node's table: the reference path on its mesh (DEFAULT_REF_SPEC) through
    DEFAULT_GRID's depths, solved or taken from the cache (azimuth 0 is the full run's 3.4 mm level); returns
    (path, depths (D,) m). Raises ``SystemExit`` for an azimuth DEFAULT_GRID does not have."""
    check_azimuth(angle_deg)
    depths = push_depths(DEFAULT_GRID.depth_step)
    return stable_path(DEFAULT_REF_SPEC, angle_deg, depths, mat, cache, rm.rest_vertices.astype(float),
                       contact), depths


def node_table_report(table: dict, paths: dict[float, dict], mat: Material, key: str) -> dict:
    """What ``node_table.json`` records of the FEM node's table (:func:`build_node_table`): per azimuth the
    reference path's DOF, the loading path's CPU and the unloading sweep's wall time, the Newton iterations of
    the states kept (one branch per depth), the depths where the stable branch took the unloaded state, and
    the finger force (N), largest Green–Lagrange strain and inverted elements at every depth; plus a check
    against the finger's geometry, not against the reference the table came from: the table's displacement of
    the surface point under the fingertip along the inward normal, minus the push depth (mm; the rigid apex's
    penetration plus the surface grid's sampling), largest per azimuth. ``paths``: azimuth (deg) → its
    :func:`stable_path` dict, or None when not cached (its facts are then left out). Units in keys."""

    R, c = float(table["radius"]), np.asarray(table["center"], float)
    phis = np.asarray(table["angles"], float)
    depths = np.asarray(table["depths"], float)
    pts = np.column_stack([c[0] + R * np.cos(phis), np.full(len(phis), c[1]), c[2] + R * np.sin(phis)])
    sm = SnapshotModel(table, pts, E=mat.E)
    reused = reused_azimuths(table)
    rows = []
    for i, phi in enumerate(phis):
        n_in = -np.array([math.cos(phi), 0.0, math.sin(phi)])
        apex = [float(sm.surface(float(phi), float(d))[0][i] @ n_in - d) * 1e3 for d in depths[1:]]
        p = paths.get(round(math.degrees(phi), 6))
        gone = "taken from the table this one extends (that table's report has its path's facts)" \
            if round(math.degrees(phi), 6) in reused else "not in this machine's cache"
        facts = {"path": gone} if p is None else {
            "dofs": int(p["dofs"]), "cpu_seconds_loading": float(p["cpu_seconds"]),
            "unload_seconds": float(p["unload_seconds"]) if "unload_seconds" in p else None,
            "newton_iterations": int(np.sum(p["newton"])), "converged": bool(np.all(p["converged"])),
            "unloaded_state_at_mm": [round(float(d) * 1e3, 3) for d in depths[1:][
                np.asarray(p.get("branch", np.zeros(len(depths) - 1))) == 1]]}
        rows.append({"azimuth_deg": round(math.degrees(phi), 6), **facts, "force_N": sm.force[i].tolist(),
                     "max_strain": np.asarray(table["max_strain"])[i].tolist(),
                     "inverted": np.asarray(table["inverted"])[i].tolist(),
                     "apex_depth_error_mm": apex, "apex_depth_error_max_mm": max(abs(a) for a in apex)})
    return {"key": key, "material": {"E": mat.E, "nu": mat.nu, "Jm": mat.Jm if mat.gent else None,
                                     "law": law_name(mat)},
            "mesh": DEFAULT_REF_SPEC.__dict__, "grid": DEFAULT_GRID.key(),
            "depths_mm": (depths * 1e3).tolist(),
            "table_MB_float32": float(sum(np.asarray(table[k]).size * 4 for k in ("side", "cap")) / 1e6),
            "apex_check": "the table's displacement of the surface point under the fingertip along the "
                          "inward normal minus the push depth: the finger's geometry, not the reference it "
                          "came from",
            "azimuths": rows}


TWIN_DR = 0.0001    #: m: a twin mesh's wider refinement tube (:func:`twin_spec`)


def twin_spec(spec: RefSpec) -> RefSpec:
    """The **twin** of a reference mesh: the same sizes, the refinement tube :data:`TWIN_DR` wider, so gmsh
    lays the elements out anew. The same push on a mesh and on its twin differs by that mesh's noise, which no
    interpolation between pushes solved on such meshes can beat."""
    return replace(spec, refine_radius=spec.refine_radius + TWIN_DR)


#: a table check's target: the largest visible shape error, projector px
TARGET_PX = 1.0


def _fingers(rm, azimuth_deg: float, depths) -> list:
    return [finger_at(math.radians(azimuth_deg), float(d), FINGER_R, rm.mesh.radius, rm.mesh.center)
            for d in depths]


def _table_px(rm, table: dict, mat: Material, azimuth_deg: float, depths, ref_u) -> list[float]:
    """The table's visible shape error (px, :func:`flexsheet.fem.eye_judge.shape_px_by_depth`) per depth at
    ``azimuth_deg`` against the reference displacements ``ref_u`` (D, k, 3) m of the rendered vertices."""
    verts = rm.rest_vertices.astype(float)
    sm = SnapshotModel(table, verts, E=mat.E)
    u = np.stack([sm.surface(math.radians(azimuth_deg), float(d), 0.0)[0] for d in depths])
    return shape_px_by_depth(u, np.asarray(ref_u, float), verts, np.asarray(rm.faces),
                             _fingers(rm, azimuth_deg, depths))


def node_table_holdout(table: dict, mat: Material, cache: ArrayCache, rm: RealtimeModel, azimuth_deg: float,
                       contact: str = DEFAULT_CONTACT, twin: bool = False) -> dict:
    """The node's table at an azimuth it does not hold, against that push's own stable path on the table's
    mesh (:func:`stable_path` on DEFAULT_REF_SPEC, solved here unless cached: ~10 min of one core): the
    interpolation across azimuth alone, every table depth, the largest visible shape error (px, what either
    eye sees, :func:`flexsheet.fem.eye_judge.shape_px_by_depth`). ``twin``: also the same push on the mesh's
    twin (:func:`twin_spec`; as long again), and that mesh's noise (``noise_px``, the same figure between the
    two). Raises ``ValueError`` for an azimuth the table holds or outside it."""

    held = np.degrees(np.asarray(table["angles"], float))
    if np.any(np.abs(held - azimuth_deg) < 1e-9) or not held[0] < azimuth_deg < held[-1]:
        raise ValueError(f"held-out azimuth must lie strictly between the table's, off them "
                         f"({held.round(6).tolist()} deg), got {azimuth_deg!r}")
    depths = np.asarray(table["depths"], float)
    verts = rm.rest_vertices.astype(float)
    p = stable_path(DEFAULT_REF_SPEC, azimuth_deg, depths[1:], mat, cache, verts, contact)
    err = _table_px(rm, table, mat, azimuth_deg, depths[1:], p["u"])
    bad = [float(d) * 1e3 for d, e in zip(depths[1:], err, strict=True) if e > TARGET_PX]
    row = {"azimuth_deg": float(azimuth_deg), "against": "its own path on the table's mesh (cut half model)",
           "depths_mm": (depths[1:] * 1e3).tolist(), "shape_px": err, "max_shape_px": max(err),
           "over_target_from_mm": min(bad) if bad else None, "dofs": int(p["dofs"]),
           "cpu_seconds_loading": float(p["cpu_seconds"])}
    if twin:
        q = stable_path(twin_spec(DEFAULT_REF_SPEC), azimuth_deg, depths[1:], mat, cache, verts, contact)
        noise = shape_px_by_depth(np.asarray(q["u"], float), np.asarray(p["u"], float), verts,
                                  np.asarray(rm.faces),
                                  _fingers(rm, azimuth_deg, depths[1:]))
        row["twin"] = {"spec": twin_spec(DEFAULT_REF_SPEC).__dict__, "dofs": int(q["dofs"]),
                       "converged": bool(np.all(q["converged"])), "noise_px": noise,
                       "max_noise_px": max(noise),
                       "what": "the same push on the twin mesh (same sizes, the tube 0.1 mm wider, laid out "
                               "anew) against the table mesh's solve, the same vertices: the mesh's noise"}
    return row


def node_table_compare(tables: dict[str, dict], azimuths, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                       contact: str = DEFAULT_CONTACT) -> list[dict]:
    """Several tables (name → table, e.g. the node's before and after azimuths were added) judged at the same
    held-out ``azimuths`` (deg) as :func:`node_table_holdout` judges each (its push solved unless cached). One
    row per azimuth: {"azimuth_deg", "depths_mm", and per name {"shape_px" (rounded to 0.001 px),
    "max_shape_px", "over_target_from_mm"} or "holds this azimuth" where that table holds it}."""
    rows = []
    for az in (float(a) for a in azimuths):
        row: dict = {"azimuth_deg": az}
        for name, tab in tables.items():
            if np.any(np.abs(np.degrees(np.asarray(tab["angles"], float)) - az) < 1e-9):
                row[name] = "holds this azimuth"
                continue
            r = node_table_holdout(tab, mat, cache, rm, az, contact)
            row[name] = {"shape_px": [round(e, 3) for e in r["shape_px"]],
                         "max_shape_px": round(r["max_shape_px"], 3),
                         "over_target_from_mm": r["over_target_from_mm"]}
            row["depths_mm"] = r["depths_mm"]
        rows.append(row)
    return rows


def node_table_between_depths(table: dict, mat: Material, cache: ArrayCache, rm: RealtimeModel,
                              azimuth_deg: float, contact: str = DEFAULT_CONTACT) -> dict:
    """The node's table between its depths, at one of its azimuths: against that push's own stable path on the
    table's mesh solved at **half** the table's load step (:func:`stable_path` on DEFAULT_REF_SPEC through
    depths every step/2 to the table's deepest; solved unless cached: ~20 min of one core at azimuth 0, the
    quarter model). Judged as :func:`node_table_holdout` judges (the largest visible shape error, px) at every
    depth of that path: the midpoints are the interpolation in depth, and with a bistable push they show what
    blending two branches' states costs; at the table's own depths the two sides differ only by float16
    rounding and by a branch that the finer load step may leave elsewhere. Returns per-depth errors, the
    largest at the midpoints and at the table's depths, and the depths where each side holds the unloaded
    (stable-branch) state. Raises ``ValueError`` for an azimuth the table does not hold."""

    held = np.degrees(np.asarray(table["angles"], float))
    if not np.any(np.abs(held - azimuth_deg) < 1e-9):
        raise ValueError(f"azimuth must be one of the table's ({held.round(6).tolist()} deg), got "
                         f"{azimuth_deg!r}")
    depths = np.asarray(table["depths"], float)
    step = float(depths[1] - depths[0])
    fine = np.round(np.arange(1, int(round(depths[-1] / (step / 2))) + 1) * (step / 2), 9)
    verts = rm.rest_vertices.astype(float)
    p = stable_path(DEFAULT_REF_SPEC, azimuth_deg, fine, mat, cache, verts, contact)
    err = np.array(_table_px(rm, table, mat, azimuth_deg, fine, p["u"]))
    mid = np.abs(np.round(fine / step) * step - fine) > 1e-9
    bad = fine[err > TARGET_PX]
    return {"azimuth_deg": float(azimuth_deg),
            "against": f"its own stable path on the table's mesh, load step {step / 2 * 1e3:g} mm",
            "depths_mm": (fine * 1e3).tolist(), "shape_px": err.tolist(), "max_shape_px": float(err.max()),
            "max_shape_px_between_depths": float(err[mid].max()),
            "max_shape_px_at_table_depths": float(err[~mid].max()),
            "over_target_from_mm": float(bad.min() * 1e3) if len(bad) else None,
            "unloaded_state_at_mm": (fine[np.asarray(p["branch"]) == 1] * 1e3).tolist() if "branch" in p
            else None,
            "dofs": int(p["dofs"]), "cpu_seconds_loading": float(p["cpu_seconds"])}


def table_update_ms(table: dict, verts: np.ndarray, mat: Material, n: int = 50) -> dict:
    """CPU time (``time.thread_time``) of one snapshot look-up for the rendered vertices ``verts`` (k, 3) m —
    what the node does per update on the cylinder (:meth:`flexsheet.fem.snapshots.SnapshotModel.surface`) — at
    pushes between the table's azimuths (the first, middle and last midpoints: 5°, 35°, 55° for the node's)
    and at 0.1, 0.4, 0.9 of its deepest push (5, 20, 45 mm), ``n`` calls each: median and 90th percentile,
    ms."""
    sm = SnapshotModel(table, verts, E=mat.E)
    mids = np.degrees(np.asarray(table["angles"], float))
    mids = (mids[:-1] + mids[1:]) / 2 if len(mids) > 1 else mids
    ts = []
    for a in sorted({float(mids[0]), float(mids[len(mids) // 2]), float(mids[-1])}):
        for d in (0.1 * sm.depth_max, 0.4 * sm.depth_max, 0.9 * sm.depth_max):
            for _ in range(n):
                t = time.thread_time()
                sm.surface(math.radians(a), d)
                ts.append(time.thread_time() - t)
    return {"median_ms": float(np.median(ts) * 1e3), "p90_ms": float(np.percentile(ts, 90) * 1e3),
            "vertices": int(len(verts)), "calls": len(ts),
            "what": "SnapshotModel.surface CPU time (thread_time) per call, the node's per-update look-up"}


def build_node_table(mat: Material, cache: ArrayCache, cache_dir: str | None, contact: str = DEFAULT_CONTACT,
                     azimuth: float | None = None, jobs: int = 1, ship: bool = False, out: str | None = None,
                     holdout: tuple[float, ...] = (), between: tuple[float, ...] = (), twin: bool = False,
                     plot=None) -> int:
    """Build (or find) the FEM node's snapshot table: :data:`flexsheet.fem.snapshots.DEFAULT_GRID` on
    :data:`flexsheet.fem.snapshots.DEFAULT_REF_SPEC`, the key the node looks up (its ``finger_radius`` default
    is the experiment's 8 mm). Every azimuth's path is a cached :func:`node_table_path` (azimuth 0: the full
    run's 3.4 mm level), so ``azimuth`` (deg) solves just that one and returns: run the azimuths in parallel
    processes, or over several sittings, then once without it to assemble the table; without it the azimuths
    the cache lacks are solved in ``jobs`` worker processes first
    (:func:`flexsheet.fem.reference.workers.prefetch`). ``ship``: also write the table, packed
    (:func:`flexsheet.fem.reference.snapshot_build.pack_table`: float16 surface fields, compressed), into the
    repository's ``flexsheet/fem/data/`` (:meth:`flexsheet.fem.cache.ArrayCache.ship`), where the node finds
    it on a machine that never solved it. A table on fewer azimuths in the cache or the shipped store
    (:func:`flexsheet.fem.reference.snapshot_build.reusable_table`) is extended: only the azimuths it lacks
    are solved. ``out``: write ``node_table.json`` there (:func:`node_table_report`), with the table judged at
    each ``holdout`` azimuth (deg, between the table's) against its own solve (:func:`node_table_holdout`;
    solved unless cached) and between its depths at each ``between`` azimuth (deg, one of the table's;
    :func:`node_table_between_depths`); ``twin`` (``--mesh-check``): each held-out push also on the mesh's
    twin, its noise beside the error; ``plot``: callable (out, report) that draws the report beside it
    (``node_table.png``, :func:`flexsheet.experiments.fem.plots.plot_node_table`). Returns 0."""
    st = replace(settings_for(False), grid=DEFAULT_GRID, snap_spec=DEFAULT_REF_SPEC, contact=contact)
    t0 = time.perf_counter()
    rm = realtime_model(st, mat, cache_dir)
    if azimuth is not None:
        node_table_path(azimuth, mat, cache, rm, contact)
        log.info(f"node table: azimuth {azimuth:g} deg cached in {time.perf_counter() - t0:.0f} s")
        return 0
    key = table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, mat.nu, FINGER_R, contact, mat.Jm)
    log.info(f"node table: azimuths {DEFAULT_GRID.angles_deg} deg on {DEFAULT_REF_SPEC.key()}; key {key}")
    table = _find_or_build(st, mat, cache, rm, jobs, t0)
    verts = rm.rest_vertices.astype(float)
    depths = push_depths(DEFAULT_GRID.depth_step)
    paths = {a: cached_path(DEFAULT_REF_SPEC, a, depths, mat, cache, verts, contact)
             for a in DEFAULT_GRID.angles_deg}
    shipped = _ship(table, paths, mat, cache, contact) if ship else None
    if out and holdout:     # the held-out pushes (and their twins) the cache lacks, in worker processes
        specs = [DEFAULT_REF_SPEC] + ([twin_spec(DEFAULT_REF_SPEC)] if twin else [])
        prefetch([Solve(sp, a, DEFAULT_GRID.depth_step, stable=True) for a in holdout for sp in specs], jobs,
                 mat,
                 cache, verts, contact)
    if out:
        rep = node_table_report(table, paths, mat, key)
        if shipped is not None:
            rep["shipped"] = shipped
        _judge(rep, table, mat, cache, rm, contact, holdout, between, twin)
        _write(out, "node_table", rep)
        if plot is not None:
            plot(out, rep)
        log.info(f"node table report -> {out}/node_table.json")
    return 0


def _find_or_build(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, jobs: int,
                   t0: float) -> dict:
    """The node's table from the cache or the shipped store, else built (:func:`build_node_table`): a table on
    fewer azimuths extended, the paths the cache lacks solved in ``jobs`` workers first."""
    contact = st.contact
    table, hit, _ = load_or_build(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, FINGER_R, build=False,
                                  contact=contact)
    if hit:  # in the cache or shipped: its paths are not solved again (a held-out check needs only its own)
        log.info("node table found (this machine's cache or flexsheet/fem/data): not solving its paths again")
        return table
    base = reusable_table(cache, DEFAULT_GRID, DEFAULT_REF_SPEC, mat, FINGER_R, contact)
    have = set() if base is None else {round(float(a), 6) for a in np.degrees(base["angles"])}
    if base is not None:
        log.info(f"node table: extending the table on azimuths {sorted(have)} deg (this machine's cache or "
                 f"flexsheet/fem/data): only {[a for a in DEFAULT_GRID.angles_deg if a not in have]} deg are "
                 "solved")
    prefetch([Solve(DEFAULT_REF_SPEC, a, DEFAULT_GRID.depth_step, stable=True)
              for a in DEFAULT_GRID.angles_deg
              if a not in have], jobs, mat, cache, rm.rest_vertices.astype(float), contact)

    def solved(ang, model, depths):
        states = path_states(*node_table_path(ang, mat, cache, rm, contact), depths, model)
        if states is None:          # else build_table would solve it again, uncached
            raise RuntimeError(f"the node table's path at {ang:g} deg lacks a depth of {DEFAULT_GRID.key()}")
        return states

    table, _, sec = snapshot_table(st, mat, cache, solved, reuse=base)
    log.info(f"node table built in {sec:.0f} s: {sum(v.nbytes for v in table.values()) / 1e6:.0f} MB; total "
             f"{time.perf_counter() - t0:.0f} s. The FEM node loads it at start (model: auto)")
    return table


def _ship(table: dict, paths: dict[float, dict | None], mat: Material, cache: ArrayCache,
          contact: str) -> dict:
    """Write ``table``, packed, into the shipped store (``--ship``); what ``node_table.json`` records of it.
    ``SystemExit`` when an azimuth's path is unconverged or not in this machine's cache (so not checked)."""
    # an azimuth copied from an extended table was checked
    # when that table shipped (or was built from this cache)
    reused = reused_azimuths(table)
    missing = [a for a, q in paths.items() if q is None and round(a, 6) not in reused]
    unconverged = [a for a, q in paths.items() if q is not None and not np.all(q["converged"])]
    if missing or unconverged:
        raise SystemExit("flexsheet experiment fem: not shipping the node table: Newton did not converge at "
                         f"every load step at azimuth(s) {unconverged} deg, paths not in this machine's "
                         f"cache (so not checked) at {missing} deg")
    packed, err = pack_table(table)
    p = cache.ship("snapshots", table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, mat.nu, FINGER_R, contact, mat.Jm),
                   packed)
    log.info(f"node table shipped: {p} ({os.path.getsize(p) / 1e6:.1f} MB, float16 surface fields: rounding "
             f"<= {err * 1e3:.4f} mm); commit it")
    return {"path": os.path.relpath(p, os.getcwd()), "MB": os.path.getsize(p) / 1e6,
            "float16_rounding_mm": err * 1e3}


def _judge(rep: dict, table: dict, mat: Material, cache: ArrayCache, rm: RealtimeModel, contact: str,
           holdout: tuple[float, ...], between: tuple[float, ...], twin: bool) -> None:
    """Add to ``rep`` (:func:`node_table_report`) the table's look-up time, its errors at the ``holdout``
    azimuths and between its depths at the ``between`` ones, and log them."""
    rep["update"] = table_update_ms(table, rm.rest_vertices.astype(float), mat)
    rep["held_out"] = [node_table_holdout(table, mat, cache, rm, a, contact, twin) for a in holdout]
    rep["between_depths"] = [node_table_between_depths(table, mat, cache, rm, a, contact) for a in between]
    for h in rep["between_depths"]:
        log.info(f"node table between its depths at {h['azimuth_deg']:g} deg: worst visible shape "
                 f"{h['max_shape_px_between_depths']:.2f} px (at its own depths "
                 f"{h['max_shape_px_at_table_depths']:.2f})")
    for h in rep["held_out"]:
        log.info(f"node table held out at {h['azimuth_deg']:g} deg: worst visible shape "
                 f"{h['max_shape_px']:.2f} px"
                 + (f", over the target from {h['over_target_from_mm']:g} mm" if h["over_target_from_mm"]
                    else ""))


def _write(out: str, name: str, data: dict) -> None:
    with open(os.path.join(out, name + ".json"), "w") as fh:
        json.dump(data, fh, indent=1)
