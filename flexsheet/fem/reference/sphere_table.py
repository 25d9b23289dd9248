"""The sphere scene's nonlinear table: ``flexsheet experiment fem --scene launch/scenes/sphere.yaml
--node-table [--azimuth A] [--holdout-azimuth A ...] [--jobs N] --out DIR`` (wired by
:mod:`flexsheet.experiments.fem`; for the sphere "azimuth" is the polar angle α of the push from the support
axis, along the stroke).

1. Every snapshot angle of :data:`flexsheet.fem.sphere_snapshots.DEFAULT_SPHERE_GRID` is solved
   (:func:`flexsheet.fem.reference.sphere_build.solve_alpha`: the scene's hyperelastic body, full body, mesh
   refined along that push path, 0 → 50 mm, stable branch), each cached apart (``--azimuth A`` solves one and
   exits; ``--jobs`` solves the missing ones in worker processes); the table is assembled and stored under the
   key the FEM node looks up (:func:`flexsheet.fem.sphere_snapshots.sphere_table_key`).
2. ``DIR/sphere_table.json`` + ``.png``: per angle the DOF, CPU, Newton convergence, the depths where the
   stable branch took the unloaded state, the force against depth, and Hertz's force at the first depth
   (Johnson §4.2, the rigid sphere of the finger's radius on the sphere: a closed form, not the reference);
   the look-up time; and each **held-out** angle (``--holdout-azimuth``, between the table's): its own solve
   on its own mesh against the table (interpolation across α) and against the linear real-time model the node
   served before (:class:`flexsheet.fem.scene_model.SceneModel`), as the largest distance over the visible
   rendered vertices (not held, outside the finger's footprint: deformed position > finger radius + 2 mm from
   the push axis).

3. ``--mesh-check``: at each held-out angle (else 0°) the same push on the table mesh's **twin** (same sizes,
   laid out anew) and on each of :data:`MESH_STUDY_SPECS` and its twin (:func:`mesh_study_specs`): each mesh's
   noise, each against the table's mesh, and the table against each (``mesh_check``, a list per angle; null
   without the flag). Units in keys (mm, ms, N), else SI.
"""

from __future__ import annotations

import logging
import math
import os
import time

import numpy as np

from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache, cache_key
from flexsheet.fem.choose import visible_mask
from flexsheet.fem.eye_judge import shape_px_by_depth
from flexsheet.fem.material import Material
from flexsheet.fem.reference.node_table import TWIN_DR
from flexsheet.fem.reference.sphere_build import assemble_table, solve_alpha
from flexsheet.fem.reference.versions import SOLVER_VERSION, UNLOAD_VERSION
from flexsheet.fem.reference.workers import parallel, run_workers
from flexsheet.fem.scene_model import SceneModel, finger_on_scene
from flexsheet.fem.sphere_snapshots import (
    DEFAULT_SPHERE_GRID,
    DEFAULT_SPHERE_SPEC,
    SPHERE_TABLE_VERSION,
    SphereSnapshotModel,
    sphere_frame,
    sphere_table_key,
)
from flexsheet.model.scenes import load_scene

log = logging.getLogger(__name__)

__all__ = ["build_sphere_table", "alpha_path"]

TARGET_PX = 1.0      #: a table's largest visible shape error, projector px
#: the meshes ``--mesh-check`` sets beside the table's (h, h_fine, refine radius, path depth) m (the
#: 4.5 mm table mesh's noise sits on the crater's rim, material that rested 15–28
#: mm from the push axis, outside its 15 mm tube; so the levels widen the tube)
MESH_STUDY_SPECS = ((0.012, 0.006, 0.030, 0.055),)


def _alpha_key(sc, a: float, grid, spec, probes: np.ndarray) -> str:
    import gmsh

    return cache_key("sphere-alpha-1", SPHERE_TABLE_VERSION, sc.key(), grid.key(),
                     *(f"{x:.9g}" for x in spec),
                     f"{a:.9g}", gmsh.__version__, SOLVER_VERSION, UNLOAD_VERSION,
                     cache_key(np.round(probes, 9).tobytes()))


def alpha_path(sc, a: float, grid, spec, probes: np.ndarray, cache) -> dict:
    """:func:`flexsheet.fem.reference.sphere_build.solve_alpha` at ``a`` deg, cached (kind "spherealpha")."""
    z, _, _ = cache.get_or_compute("spherealpha", _alpha_key(sc, a, grid, spec, probes),
                                   lambda: solve_alpha(sc, a, grid, spec, probes),
                                   f"sphere push at {a:g} deg on h_fine {spec[1] * 1e3:g} mm")
    return z


def _job(args) -> tuple[float, float, str | None]:
    """Worker: one angle into the cache (one BLAS thread)."""
    scene_file, a, cache_dir, spec = args
    t = time.perf_counter()
    try:
        sc = load_scene(scene_file)
        probes = SceneModel(sc, cache_dir=cache_dir).rest_vertices.astype(float)
        alpha_path(sc, a, DEFAULT_SPHERE_GRID, spec, probes, ArrayCache(cache_dir))
        return a, time.perf_counter() - t, None
    except Exception as exc:  # noqa: BLE001 - reported; the run solves it itself and raises
        return a, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"


def _hertz_force(E: float, nu: float, r_finger: float, R: float, d: float) -> float:
    """Hertz's force (N) of a rigid sphere (radius ``r_finger``) pressed ``d`` m into an elastic sphere
    (radius ``R``): F = 4/3 E* √R* d^{3/2}, 1/R* = 1/r + 1/R, E* = E/(1 − ν²) (Johnson, Contact Mechanics,
    §4.2)."""
    Rs = 1.0 / (1.0 / r_finger + 1.0 / R)
    return 4.0 / 3.0 * E / (1.0 - nu ** 2) * math.sqrt(Rs) * d ** 1.5


def _check_sphere_args(sc, al, alpha: float | None, holdout: tuple[float, ...]):
    """The scene's sphere frame, after the arguments are checked (``SystemExit`` with the reason)."""
    try:
        fr = sphere_frame(sc)
    except ValueError as exc:
        raise SystemExit("flexsheet experiment fem: --node-table with --scene builds the sphere's table "
                         f"only (its symmetry: {exc})") from None
    for a in holdout:
        if not (math.isfinite(a) and al[0] < a < al[-1]) or a in al:
            raise SystemExit("flexsheet experiment fem: --holdout-azimuth must lie strictly between the "
                             f"sphere table's angles {[f'{x:g}' for x in al]} deg and off them, got {a:g}")
    if alpha is not None and not (math.isfinite(alpha) and 0 <= alpha < 90):
        raise SystemExit("flexsheet experiment fem: --azimuth (the sphere's polar angle) must be in [0, 90) "
                         f"deg, got {alpha:g}")
    return fr


def _solve_missing(scene_file, sc, grid, spec, probes, cache, cache_dir, table, holdout, check_angles,
                   mesh_check: bool, jobs: int) -> None:
    """The pushes this run needs and the cache lacks, solved in ``jobs`` worker processes (with ``jobs`` >
    1)."""
    al = grid.alphas_deg
    want = [(a, s) for a in check_angles for s in mesh_study_specs(spec).values()] if mesh_check else []
    want.sort(key=lambda x: x[1][1])  # the finest (longest) first: the workers end together
    want += [(a, spec) for a in (list(al) if table is None else [])] + [(a, spec) for a in holdout]
    # a held-out push is also the mesh study's table-mesh push: solve it once
    want = list(dict.fromkeys(want))
    todo = [(a, s) for a,
            s in want if not os.path.exists(cache.path("spherealpha", _alpha_key(sc, a, grid, s, probes))
                                            or "")]

    if parallel(jobs) and len(todo) > 1:
        log.info(f"{len(todo)} sphere pushes the cache lacks, in {min(jobs, len(todo))} worker processes")

        for a, sec, err in run_workers(_job, [(scene_file, a, cache_dir, s) for a, s in todo],
                                       min(jobs, len(todo))):
            log.info(f"sphere push at {a:g} deg: "
                     + (f"done in {sec:.0f} s" if err is None else f"failed ({err})"))


def _table_and_paths(sc, fr, grid, spec, probes, cache, key, table, E: float):
    """The table (assembled from the pushes and cached when ``table`` is None) and the snapshot angles' pushes
    (None where the cache lacks one)."""
    al = grid.alphas_deg
    if table is None:
        paths = [alpha_path(sc, a, grid, spec, probes, cache) for a in al]
        table = assemble_table(fr, grid, paths, E)
        cache.save("spheresnap", key, table)
        log.info(f"sphere table assembled: {table['field'].nbytes / 1e6:.0f} MB float32, key {key}")
    else:
        paths = [cache.load("spherealpha", _alpha_key(sc, a, grid, spec, probes)) for a in al]
    return table, paths


def _shipped_report(table, paths, al, key, cache, fr, rt, probes, r: float, out, ship: bool) -> dict | None:
    """With ``ship``: the packed table written into the shipped store (``SystemExit`` when a push is
    unconverged or not cached); else the one already shipped, when reporting. Its path, size and packing
    error, or None."""
    shipped = None
    packed = sp = None
    if ship:
        bad = [a for a, p in zip(al, paths, strict=True) if p is None or not np.all(p["converged"])]
        if bad:
            raise SystemExit("flexsheet experiment fem: not shipping the sphere table: Newton did not "
                             f"converge at every depth, or the push is not in this machine's cache, at {bad} "
                             "deg")
        packed = pack_sphere_table(table)
        sp = cache.ship("spheresnap", key, packed)
    # already shipped: report what the node reads from the store
    elif out and all(p is not None for p in paths):
        store = ArrayCache(None)                      # the shipped store alone
        packed = store.load("spheresnap", key)
        sp = store.source
    if packed is not None:
        err = _packing_error(table, packed, paths, fr, rt, probes, r)
        shipped = {"path": os.path.relpath(sp, os.getcwd()), "MB": os.path.getsize(sp) / 1e6,
                   "packing": "surface field as float16 on every second grid line (2° cells)",
                   "packing_error_mm": err}
        if ship:
            log.info(f"sphere table shipped: {sp} ({shipped['MB']:.1f} MB; packed against the full table: <= "
                     f"{err:.3f} "
                 "mm on the visible surface); commit it")
        else:
            shipped["note"] = "shipped before this run; its packing error measured again"
    return shipped


def _alpha_rows(table, paths, al, depths, mat, r: float, fr) -> list[dict]:
    """Per snapshot angle: its force against depth, its solve's figures and its force over Hertz's."""
    rows = []
    for a, p in zip(al, paths, strict=True):
        row = {"alpha_deg": a, "force_N": np.asarray(table["force"][al.index(a)]).tolist()}
        if p is not None:
            br = np.asarray(p["branch"])
            row.update(dofs=int(p["dofs"]), cpu_seconds_loading=float(p["cpu_seconds"]),
                       unload_seconds=float(p["unload_seconds"]), converged=bool(np.all(p["converged"])),
                       newton_iterations=int(np.sum(p["newton"])), max_inverted=int(np.max(p["inverted"])),
                       unloaded_state_at_mm=(depths[br == 1] * 1e3).tolist())
        else:
            row["path"] = "not in this machine's cache"
        h = _hertz_force(mat.E, mat.nu, r, fr.radius, depths[1])
        row["force_over_hertz_at_first_depth"] = float(table["force"][al.index(a)][1] / h)
        rows.append(row)
    return rows


def _held_out_rows(sc, fr, sm, rt, probes, grid, spec, cache, holdout, depths, r: float) -> list[dict]:
    """Per held-out angle: its own push against the table and against the linear model, on the visible
    surface."""
    held_out = []
    for a in holdout:
        p = alpha_path(sc, a, grid, spec, probes, cache)
        n = fr.direction(math.radians(a))
        q = fr.center + fr.radius * n
        snap = np.stack([sm.surface(n, float(d))[0] if d > 0 else np.zeros_like(probes) for d in depths])
        lin = np.stack([rt.surface_displacement(finger_on_scene(q, n, float(d), r))[0] if d > 0 else
                        np.zeros_like(probes) for d in depths])
        ref = np.asarray(p["u_probes"], float)
        fingers = [finger_on_scene(q, n, float(d), r) for d in depths[1:]]
        faces = np.asarray(rt.faces)
        e_s = shape_px_by_depth(snap[1:], ref[1:], probes, faces, fingers)
        e_l = shape_px_by_depth(lin[1:], ref[1:], probes, faces, fingers)
        bad = [float(d) * 1e3 for d, e in zip(depths[1:], e_s, strict=True) if e > TARGET_PX]
        held_out.append({"alpha_deg": a, "against": "its own push on its own mesh (same sizes), "
                                                    f"{sc.finger.contact}",
                         "depths_mm": (depths[1:] * 1e3).tolist(), "snapshots_shape_px": e_s,
                         "linear_shape_px": e_l, "max_snapshots_shape_px": max(e_s),
                         "max_linear_shape_px": max(e_l),
                         "over_target_from_mm": min(bad) if bad else None, "dofs": int(p["dofs"]),
                         "converged": bool(np.all(p["converged"]))})
        log.info(f"held out {a:g} deg: snapshots {max(e_s):.2f} px, linear {max(e_l):.2f} px worst")
    return held_out


def _lookup_times(fr, sm) -> list[float]:
    """CPU seconds (thread time) of the table's look-up, 30 calls at each of 3 angles x 3 depths."""
    ts = []
    for a in (5.0, 35.0, 55.0):
        n = fr.direction(math.radians(a))
        for d in (0.005, 0.02, 0.045):
            for _ in range(30):
                t = time.thread_time()
                sm.surface(n, d)
                ts.append(time.thread_time() - t)
    return ts


def _sphere_report(sc, mat, key, grid, spec, table, depths, rows, ts, probes, held_out, shipped, t0) -> dict:
    """The report's JSON (``mesh_check`` still null)."""
    al = grid.alphas_deg
    return {"scene": {"name": sc.name,
                      "file": os.path.relpath(str(sc.source), os.getcwd()) if sc.source else None,
                      "key": sc.key()},
            "material": {"law": sc.material.model, "E": mat.E, "nu": mat.nu,
                         "Jm": mat.Jm if mat.gent else None},
            "key": key, "grid": {"alphas_deg": list(al), "depth_step_mm": grid.depth_step * 1e3,
                                 "depth_max_mm": grid.depth_max * 1e3, "dtheta_deg": grid.dtheta_deg,
                                 "dphi_deg": grid.dphi_deg},
            "mesh": {"h_m": spec[0], "h_fine_m": spec[1], "refine_radius_m": spec[2],
                     "path_depth_m": spec[3]},
            "table_MB_float32": table["field"].nbytes / 1e6, "depths_mm": (depths * 1e3).tolist(),
            "alphas": rows,
            "update": {"median_ms": float(np.median(ts) * 1e3), "p90_ms": float(np.percentile(ts, 90) * 1e3),
                       "vertices": int(len(probes)), "calls": len(ts),
                       "what": "SphereSnapshotModel.surface CPU time (thread_time) per call"},
            "held_out": held_out, "mesh_check": None, "target_px": TARGET_PX, "shipped": shipped,
            "footprint": "vertices whose deformed (reference) position lies within finger radius + 2 mm of "
                         "the push axis are hidden by the finger and left out, as for the cylinder",
            "wall_s": time.perf_counter() - t0}


def build_sphere_table(scene_file: str, out: str | None, cache_dir: str | None, alpha: float | None = None,
                       holdout: tuple[float, ...] = (), jobs: int = 1, mesh_check: bool = False,
                       ship: bool = False) -> int:
    """Build (or find) the sphere scene's table and report it (module doc); ``ship``: also write it, packed
    (the surface field as float16, compressed), into the repository's ``flexsheet/fem/data/``, where the FEM
    node finds it on a machine that never solved it. Returns 0; ``SystemExit`` with the reason for a scene the
    table does not apply to, a bad angle, or a table that may not be shipped (an angle unconverged or not
    cached)."""

    t0 = time.perf_counter()
    sc = load_scene(scene_file)
    grid, spec = DEFAULT_SPHERE_GRID, DEFAULT_SPHERE_SPEC
    al = grid.alphas_deg
    fr = _check_sphere_args(sc, al, alpha, holdout)
    cache_dir = cache_dir or DEFAULT_CACHE_DIR
    cache = ArrayCache(cache_dir)
    rt = SceneModel(sc, cache_dir=cache_dir)
    probes = rt.rest_vertices.astype(float)
    if alpha is not None:
        alpha_path(sc, alpha, grid, spec, probes, cache)
        log.info(f"sphere push at {alpha:g} deg cached in {time.perf_counter() - t0:.0f} s")
        return 0
    key = sphere_table_key(sc, grid, spec)
    table = cache.load("spheresnap", key)
    check_angles = tuple(holdout) or (0.0,)
    _solve_missing(scene_file, sc, grid, spec, probes, cache, cache_dir, table, holdout, check_angles,
                   mesh_check,
                   jobs)
    mat = Material.of_scene(sc.material)
    table, paths = _table_and_paths(sc, fr, grid, spec, probes, cache, key, table, mat.E)
    shipped = _shipped_report(table, paths, al, key, cache, fr, rt, probes, sc.finger.radius, out, ship)
    if not out:
        return 0
    sm = SphereSnapshotModel(table, probes, E=mat.E)
    depths = grid.depths()
    r = sc.finger.radius
    rows = _alpha_rows(table, paths, al, depths, mat, r, fr)
    held_out = _held_out_rows(sc, fr, sm, rt, probes, grid, spec, cache, holdout, depths, r)
    ts = _lookup_times(fr, sm)
    rep = _sphere_report(sc, mat, key, grid, spec, table, depths, rows, ts, probes, held_out, shipped, t0)
    if mesh_check:
        rep["mesh_check"] = _mesh_check(sc, fr, sm, probes, np.asarray(rt.faces), grid, spec, check_angles,
                                        cache)
    os.makedirs(out, exist_ok=True)
    import json

    with open(os.path.join(out, "sphere_table.json"), "w") as fh:
        json.dump(rep, fh, indent=1)
    _plot(out, rep)
    log.info(f"sphere table report -> {out}/sphere_table.json ({time.perf_counter() - t0:.0f} s)")
    return 0


def pack_sphere_table(table: dict) -> dict:
    """The table made small enough to ship: the surface field on every second θ and φ line (2° cells for the
    default 1° grid) as float16 (:class:`flexsheet.fem.sphere_snapshots.SphereSnapshotModel` reads the axes it
    carries and widens to float32): an eighth of the bytes. ``ValueError`` when the grid's line counts are
    even (the last line would be lost) or a value does not fit float16."""
    f = np.asarray(table["field"], np.float32)
    if len(table["theta"]) % 2 == 0 or len(table["phi"]) % 2 == 0:
        raise ValueError(f"sphere table grid must have odd line counts to halve, got {len(table['theta'])} x "
                         f"{len(table['phi'])}")
    if not np.all(np.abs(f) < np.finfo(np.float16).max):
        raise ValueError("sphere table field does not fit float16")
    return {**table, "field": f[:, :, ::2, ::2].astype(np.float16), "theta": np.asarray(table["theta"])[::2],
            "phi": np.asarray(table["phi"])[::2]}


def _packing_error(table, packed, paths, fr, rt, probes, r) -> float:
    """Largest distance (mm) between the packed and the full table's surfaces over the visible rendered
    vertices, at every snapshot angle and depth (the footprint taken on the reference's deformed surface)."""
    full, small = SphereSnapshotModel(table, probes), SphereSnapshotModel(packed, probes)
    held = rt.held
    worst = 0.0
    for i, a in enumerate(np.degrees(np.asarray(table["alphas"], float))):
        n = fr.direction(math.radians(a))
        q = fr.center + fr.radius * n
        ref = np.asarray(paths[i]["u_probes"], float)
        for j, d in enumerate(np.asarray(table["depths"], float)[1:], start=1):
            vis = visible_mask(probes + ref[j], finger_on_scene(q, n, float(d), r)) & ~held
            e = np.linalg.norm(small.surface(n, float(d))[0] - full.surface(n, float(d))[0], axis=1)[vis]
            worst = max(worst, float(e.max()) * 1e3)
    return worst


def mesh_study_specs(spec) -> dict:
    """The meshes of ``--mesh-check``, name → (h, h_fine, refine radius, path depth) m: the table's ``spec``
    and each of :data:`MESH_STUDY_SPECS` (``level1`` …), each with its **twin** (``…_twin``: the same sizes,
    the refinement tube ``TWIN_DR`` wider, as the cylinder's twins
    (:func:`flexsheet.fem.reference.node_table.twin_spec`), so gmsh lays the elements out anew; the difference
    between a mesh and its twin is that mesh's noise, which no interpolation between pushes can beat)."""
    def twin(x):
        return (x[0], x[1], x[2] + TWIN_DR, x[3])

    out = {}
    for name, x in (("table", tuple(spec)),
                    *((f"level{i + 1}", tuple(m)) for i, m in enumerate(MESH_STUDY_SPECS))):
        out[name], out[name + "_twin"] = x, twin(x)
    return out


def _mesh_check(sc, fr, sm, probes, faces, grid, spec, angles, cache) -> list[dict]:
    """For each angle (the held-out ones, else 0°) and each mesh of :func:`mesh_study_specs` (the table's, its
    twin, the study's levels and their twins): the push solved on it, compared by the visible shape
    (:func:`flexsheet.fem.eye_judge.shape_px_by_depth`, px) at every depth: each mesh's noise (against
    its twin), each level against the table's mesh, and the table (interpolated in α) against each."""
    depths = grid.depths()[1:]
    r = sc.finger.radius
    specs = mesh_study_specs(spec)
    out = []
    for a in angles:
        n = fr.direction(math.radians(a))
        q = fr.center + fr.radius * n
        sols = {k: alpha_path(sc, a, grid, x, probes, cache) for k, x in specs.items()}
        u = {k: np.asarray(v["u_probes"], float)[1:] for k, v in sols.items()}
        snap = np.stack([sm.surface(n, float(d))[0] for d in depths])
        fingers = [finger_on_scene(q, n, float(d), r) for d in depths]

        def diff(x, y, fingers=fingers):
            return shape_px_by_depth(x, y, probes, faces, fingers)

        levels = []
        for k, x in specs.items():
            if k.endswith("_twin"):
                continue
            lv = {"name": k, "spec_m": list(x), "dofs": int(sols[k]["dofs"]),
                  "dofs_twin": int(sols[k + "_twin"]["dofs"]),
                  "converged": bool(np.all(sols[k]["converged"]) and np.all(sols[k + "_twin"]["converged"])),
                  "cpu_seconds": float(sols[k]["cpu_seconds"]) + float(sols[k]["unload_seconds"]),
                  "force_N_at_max_depth": float(sols[k]["force"][-1]),
                  "noise_px": diff(u[k], u[k + "_twin"]), "snapshots_vs_this_px": diff(snap, u[k])}
            lv["vs_table_mesh_px"] = diff(u[k], u["table"])
            lv["max_noise_px"] = max(lv["noise_px"])
            levels.append(lv)
            log.info(f"mesh study at {a:g} deg, {k} (h_fine {x[1] * 1e3:g} mm, tube {x[2] * 1e3:g} mm, "
                 f"{lv['dofs']} DOF): noise {lv['max_noise_px']:.2f} px, table against it "
                 f"{max(lv['snapshots_vs_this_px']):.2f} px")
        out.append({"alpha_deg": a, "depths_mm": (depths * 1e3).tolist(), "levels": levels,
                    "what": "largest visible shape error, px: noise = the same push on the "
                            "mesh and on its twin (same sizes, laid out anew); vs_table_mesh = this mesh "
                            "against the table's; snapshots_vs_this = the table's look-up (interpolated in "
                            "α) against this mesh"})
    return out


def _plot(out: str, rep: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    d = rep["depths_mm"]
    for r in rep["alphas"]:
        a.plot(d, r["force_N"], ".-", ms=3, label=f"{r['alpha_deg']:g}°")
    a.set_xlabel("push depth (mm)")
    a.set_ylabel("finger force (N)")
    a.set_title(f"sphere table, {rep['material']['law']}, E {rep['material']['E'] / 1e3:g} kPa", fontsize=10)
    a.legend(fontsize=7, title="α")
    for h in rep["held_out"]:
        b.plot(h["depths_mm"], h["snapshots_shape_px"], "k.-", ms=4,
               label=f"snapshots, held out {h['alpha_deg']:g}°")
        b.plot(h["depths_mm"], h["linear_shape_px"], "r.--", ms=3, label=f"linear, {h['alpha_deg']:g}°")
    for m in rep.get("mesh_check") or []:
        for lv, mk in zip(m["levels"], "^vs<>", strict=False):
            b.plot(m["depths_mm"], lv["noise_px"], mk + "-", ms=3,
                   label=f"{m['alpha_deg']:g}°: noise, h_fine {lv['spec_m'][1] * 1e3:g} / tube "
                         f"{lv['spec_m'][2] * 1e3:g} mm")
    b.axhline(TARGET_PX, color="k", ls=":", lw=0.8, label=f"target {TARGET_PX:g} px")
    b.set_xlabel("push depth (mm)")
    b.set_ylabel("visible shape error (projector px)")
    b.set_yscale("log")
    b.set_title("against the nonlinear reference", fontsize=10)
    b.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "sphere_table.png"), dpi=110)
    plt.close(fig)
