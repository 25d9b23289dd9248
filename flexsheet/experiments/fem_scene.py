"""The FEM's accuracy and speed on any scene (issue 17): ``flexsheet experiment fem --scene
launch/scenes/NAME.yaml`` (wired by :mod:`flexsheet.experiments.fem`) calls :func:`run_scene`.

What it measures, for the scene's real-time model — what the FEM node serves for this scene: the nonlinear
snapshot table where the scene has one (the sphere, :mod:`flexsheet.fem.sphere_snapshots`, attached as the node
attaches it, the linear model outside it), else :class:`flexsheet.fem.scene_model.SceneModel` (linear P2,
per-element material, capacitance over the stroke path); with a table, the linear model is measured beside it
(``realtime.linear``):

1. **Update time**: wall time of one ``update_finger`` (contact, capacitance solve, strain/inversion checks,
   fold check) at pushes along the stroke, median and 90th percentile, ms.
2. **Accuracy against the nonlinear reference**: at push points on the stroke (``quick``: its middle; else
   its start, middle, end), a rigid capsule finger (the fingertip sphere and the finger behind it) pushed
   along the inward surface normal to 5…50 mm into the scene's compressible hyperelastic body (neo-Hookean or Gent; total Lagrangian P2,
   Newton with load stepping: :mod:`flexsheet.fem.hyperelastic`, full body, the scene's support and per-element
   material: the inclusions), on gmsh meshes of the scene refined around the push point
   (:func:`flexsheet.fem.scene_mesh.scene_mesh` with ``refine_at``). The error is the largest distance between
   the real-time and the reference displacement over the *visible* rendered surface vertices: not held by
   the support, and outside the finger's footprint (the vertex's deformed position in the reference lies more
   than finger radius + 2 mm from the push axis; the finger hides the footprint and the wall dragged onto its
   side, as for the cylinder, docs/fem.md). ``realtime.max_visible_error_mm_0_50``
   is the largest over depths 0–50 mm and push points.
3. **Mesh convergence of the reference**: the same push on three refinement levels (6, 4, 3 mm along the
   whole 50 mm push path, as the cylinder's reference needs); ``quick`` solves one level (8 mm around the
   push point: ~30 min on a loaded 2-core machine) and so cannot claim convergence; ``reference.converged`` when every Newton solve converged and the last
   refinement changes the visible surface by ≤ half the 0.7 mm target at every depth.
4. **Linear on the finest reference mesh** (P2, the full sparse solve): how much of the real-time model's
   error is the linear law rather than its mesh.

Outputs in ``out_dir``: ``summary.json`` (``scene``, ``realtime.update_ms``, ``realtime.update_ms_p90``,
``realtime.max_visible_error_mm_0_50``, ``realtime.error_mm_by_depth``, ``reference.model``,
``reference.converged``, ``reference.levels``, ``linear_fine``), ``accuracy_speed_<name>.png`` + ``.json``
(the same numbers). ``quick`` pushes to 30 mm only (``max_visible_error_mm_0_30``; ``…_0_50`` is null).
Reference solves are cached (:class:`flexsheet.fem.cache.ArrayCache`, key includes
``scene.key()``). Units in files: mm and ms where the key says so, else SI.

Run by hand (charts for docs/figures/scenes/)::

    python -m flexsheet.experiments.fem_scene --scene launch/scenes/sphere.yaml --quick --out docs/figures/scenes/sphere

and the FEM stiffness and sheet tension along the stroke of a launch run (:func:`compliance_along_stroke`)::

    python -m flexsheet.experiments.fem_scene --scene launch/scenes/organ.yaml --run out/organ --out docs/figures/scenes
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from flexsheet.fem.choose import visible_mask
from flexsheet.fem.path_snapshots import GRID

__all__ = ["run_scene", "main", "visible_errors", "TARGET_MM", "QUICK", "FULL"]

TARGET_MM = 0.7                      #: one projector pixel on the screen, mm
#: settings: push fractions along the stroke, recorded depths (m), load step (m), reference levels' h_fine (m)
QUICK = {"fractions": (0.5,), "depths": tuple(np.round(np.arange(1, 7) * 0.005, 4)), "step": 0.0025,
         "levels": (0.008,), "h": 0.012, "refine_radius": 0.015, "path_depth": 0.0, "n_time": 100}
#: the full run: its first level is the path table's stations' mesh (:data:`flexsheet.fem.path_snapshots.GRID`), with
#: the same outputs, so its pushes at the stroke's start, middle and end are those of a path table whose stations
#: include them (any odd count: the default 13, or 7)
FULL = {"fractions": (0.0, 0.5, 1.0),
        "depths": tuple(np.round(np.arange(1, int(round(GRID["depth_max"] / GRID["step"])) + 1) * GRID["step"], 9)),
        "step": GRID["step"], "levels": (GRID["h_fine"], 0.004, 0.003), "h": GRID["h"],
        "refine_radius": GRID["refine_radius"], "path_depth": GRID["path_depth"], "n_time": 300}


def _log(msg: str) -> None:
    print(f"[fem_scene] {msg}", file=sys.stderr, flush=True)


def scene_reference(sc, q: np.ndarray, n: np.ndarray, h_fine: float, st: dict, probes: np.ndarray, cache) -> dict:
    """The scene's hyperelastic push (its material, its finger's contact law) at surface point ``q`` (3,) m along
    −``n`` (outward unit normal (3,)) through ``st['depths']`` (D,) m (load steps ``st['step']``) on a mesh of size
    ``st['h']`` refined to ``h_fine`` m within ``st['refine_radius']`` of ``q`` (``st['path_depth']`` > 0: of the
    whole push path down to that depth); cached (kind "scenereference"). Returns arrays: ``u`` (D, k, 3) m the
    displacements at ``probes`` (k, 3) m, ``force`` (D,) N, ``converged``, ``inverted``, ``max_strain`` (D,)
    (largest principal Green–Lagrange strain), ``seconds``, ``dofs``, and the mesh (``points``, ``tets``,
    ``fixed``, ``E``, ``nu``)."""
    from flexsheet.fem.cache import cache_key
    from flexsheet.fem.hyperelastic import SOLVER_VERSION, Capsule, HyperelasticModel, solve_path_capsule
    from flexsheet.fem.material import Material
    from flexsheet.fem.mesh import MeshSpec
    from flexsheet.fem.scene_mesh import scene_mesh

    depths = np.asarray(st["depths"], float)
    path = float(st.get("path_depth", 0.0))
    key = cache_key("scene-ref-2", SOLVER_VERSION, sc.key(), h_fine, st["h"], st["refine_radius"], st["step"],
                    np.round(q, 9).tolist(), np.round(n, 9).tolist(), np.round(depths, 9).tolist(),
                    cache_key(np.round(probes, 9).tobytes()), *([f"path={path:.6g}"] if path > 0 else []))
    # refine around the push point, or (path_depth > 0) along the whole push path: balls every
    # refine_radius/3 from q down to path_depth along -n (the tube the finger travels through)
    steps = np.arange(0.0, path + 1e-12, st["refine_radius"] / 3) if path > 0 else np.zeros(1)
    refine_at = q[None] - steps[:, None] * n[None]

    def compute() -> dict:
        t = time.perf_counter()
        sm = scene_mesh(sc, MeshSpec(st["h"], h_fine, st["refine_radius"]), refine_at=refine_at)
        mat = Material.of_scene(sc.material)
        m0 = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False, E_elem=sm.E, nu_elem=sm.nu)
        model = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False, support=m0.dof_points(sm.mesh.fixed),
                                  E_elem=sm.E, nu_elem=sm.nu)
        r = sc.finger.radius
        _log(f"reference h_fine {h_fine * 1e3:g} mm at {np.round(q * 1e3, 1).tolist()} mm: {model.n} DOF ...")
        states = solve_path_capsule(model, lambda d: Capsule(q - d * n + r * n, -n, r), depths, step=st["step"],
                                    log=lambda s: _log("  " + s.strip()), label=f"scene {sc.name}",
                                    contact=sc.finger.contact)
        P = model.probe_matrix(probes)
        return {"u": np.stack([np.asarray(P @ s.u) for s in states]), "force": np.array([s.force for s in states]),
                "converged": np.array([s.converged for s in states]), "inverted": np.array([s.inverted for s in states]),
                "max_strain": np.array([s.max_strain for s in states]), "seconds": np.array(time.perf_counter() - t), "dofs": np.array(model.n),
                "points": sm.mesh.points, "tets": sm.mesh.tets, "fixed": sm.mesh.fixed, "E": sm.E, "nu": sm.nu}

    z, _, _ = cache.get_or_compute("scenereference", key, compute, f"scene reference h_fine {h_fine * 1e3:g} mm")
    return z


def _linear_fine(sc, ref: dict, q, n, depths, probes) -> tuple[np.ndarray, float]:
    """Linear P2 on the reference's mesh (full sparse solve): displacements (D, k, 3) at ``probes`` and the
    median solve time, ms."""
    from flexsheet.fem.material import Material
    from flexsheet.fem.mesh import TetMesh, surface_faces
    from flexsheet.fem.scene_model import finger_on_scene
    from flexsheet.fem.solver import FemModel, solve_full

    mesh = TetMesh(ref["points"], ref["tets"], surface_faces(ref["points"], ref["tets"]), ref["fixed"],
                   center=sc.center.copy())
    model = FemModel(mesh, Material(sc.material.E, sc.material.nu), order=2, support=sc.fixed_mask,
                     E_elem=ref["E"], nu_elem=ref["nu"])
    us, ts = [], []
    for d in depths:
        t = time.perf_counter()
        sol = solve_full(model, finger_on_scene(q, n, float(d), sc.finger.radius))
        ts.append(time.perf_counter() - t)
        us.append(model.probe(probes, sol.u_full))
    return np.stack(us), float(np.median(ts) * 1e3)


def visible_errors(model_u, ref_u, verts, held, q, n, depths, r) -> list[float]:
    """Largest distance (mm) per depth between ``model_u`` and ``ref_u`` (D, S, 3) m over the visible rendered
    vertices ``verts`` (S, 3) m: not ``held`` (S,) bool and outside the footprint of a finger of radius ``r`` m
    pushed ``depths[j]`` m at surface point ``q`` along −``n`` (:func:`flexsheet.fem.choose.visible_mask` on the
    reference's deformed positions)."""
    from flexsheet.fem.scene_model import finger_on_scene

    out = []
    for j, d in enumerate(depths):
        vis = visible_mask(verts + ref_u[j], finger_on_scene(q, n, float(d), r)) & ~held
        out.append(float(np.linalg.norm(model_u[j] - ref_u[j], axis=1)[vis].max()) * 1e3)
    return out


def _update_ms(rt, sc, depths, n_calls: int) -> dict:
    from flexsheet.fem.scene_model import finger_on_scene

    pts, nrm = sc.stroke_points(5)
    ts, cpu, methods = [], [], []
    for q, n in zip(pts, nrm, strict=True):
        for d in depths:
            fg = finger_on_scene(q, n, float(d), rt.finger_radius)
            methods.append(rt.update_finger(fg).method)
            for _ in range(n_calls):
                t, c = time.perf_counter(), time.thread_time()
                rt.update_finger(fg)
                cpu.append(time.thread_time() - c)
                ts.append(time.perf_counter() - t)
    ts, cpu = np.array(ts) * 1e3, np.array(cpu) * 1e3
    return {"median": float(np.median(cpu)), "p90": float(np.percentile(cpu, 90)),
            "wall_median": float(np.median(ts)), "wall_p90": float(np.percentile(ts, 90)), "n": int(len(ts)),
            "sparse_share": float(np.mean([m == "sparse" for m in methods])), "methods": sorted(set(methods))}


def _attach_table(sc, rt, cache) -> str | None:
    """Attach the scene's nonlinear table to the real-time model ``rt`` as the FEM node does
    (:func:`flexsheet.fem.scene_model.attach_scene_table`: a sphere's table, any other scene's path table). Returns
    where it came from ("cache" / "shipped store ..."), or None (none stored: the node serves the linear model,
    and so is measured)."""
    from flexsheet.fem.scene_model import attach_scene_table

    kind, where = attach_scene_table(rt, cache)
    if where is None:
        _log(f"no {kind} table in the cache or the shipped store: the node serves linear, measured as such")
    return where


def _scene_push(sc, rt, snap, st: dict, verts, held, cache, f: float, depths) -> dict:
    """One push point (fraction ``f`` of the stroke): the reference's levels, the real-time model (what the node
    serves, and the linear model) and linear on the finest reference mesh against the finest level."""
    from flexsheet.fem.scene_model import finger_on_scene

    q, n = sc.stroke_at([f])
    q, n = q[0], n[0]
    refs = [scene_reference(sc, q, n, h, st, verts, cache) for h in st["levels"]]
    fine = refs[-1]
    # hidden: deformed (reference) position within finger radius + 2 mm of the push axis (as the cylinder's)
    vis = [visible_mask(verts + fine["u"][j], finger_on_scene(q, n, float(d), sc.finger.radius)) & ~held
           for j, d in enumerate(depths)]
    rt_u = [rt.surface_displacement(finger_on_scene(q, n, float(d), sc.finger.radius)) for d in depths]
    err_rt = [float(np.linalg.norm(u[0] - fine["u"][j], axis=1)[vis[j]].max()) for j, u in enumerate(rt_u)]
    if snap is not None:        # what the node serves: the table inside it (radial push), linear elsewhere
        sn_up = [rt.update_finger(finger_on_scene(q, n, float(d), sc.finger.radius)) for d in depths]
        err_sn = [float(np.linalg.norm(up.vertices - verts - fine["u"][j], axis=1)[vis[j]].max())
                  for j, up in enumerate(sn_up)]
    lin_u, lin_ms = _linear_fine(sc, fine, q, n, depths, verts)
    err_lin = [float(np.linalg.norm(lin_u[j] - fine["u"][j], axis=1)[vis[j]].max()) for j in range(len(depths))]
    levels = []
    for h, r in zip(st["levels"], refs, strict=True):
        ch = [float(np.linalg.norm(r["u"][j] - fine["u"][j], axis=1)[vis[j]].max()) for j in range(len(depths))]
        levels.append({"h_fine_m": h, "dofs": int(r["dofs"]), "seconds": float(r["seconds"]),
                       "newton_converged": bool(np.all(r["converged"])), "force_N": r["force"].tolist(),
                       "inverted": r["inverted"].tolist(), "change_to_finest_mm": [e * 1e3 for e in ch]})
    last = max(levels[-2]["change_to_finest_mm"]) if len(levels) > 1 else None
    push = {"fraction": f, "point_m": q.tolist(), "normal": n.tolist(), "depths_m": depths.tolist(),
            "linear_error_mm": [e * 1e3 for e in err_rt],
            "realtime_error_mm": [e * 1e3 for e in (err_sn if snap is not None else err_rt)],
            "realtime_methods": sorted({up.method for up in sn_up}) if snap is not None else ["linear"],
            "realtime_force_N": [up.force for up in sn_up] if snap is not None else [u[1] for u in rt_u],
            "realtime_stiffness_N_per_m": [up.stiffness for up in sn_up] if snap is not None else
            [u[2] for u in rt_u],
            "linear_force_N": [u[1] for u in rt_u], "linear_stiffness_N_per_m": [u[2] for u in rt_u],
            "linear_fine_error_mm": [e * 1e3 for e in err_lin], "linear_fine_solve_ms": lin_ms,
            "reference_levels": levels, "last_refinement_change_mm": last,
            "reference_converged": bool(len(levels) > 1 and all(lv["newton_converged"] for lv in levels)
                                        and last is not None and last <= TARGET_MM / 2)}
    _log(f"push at {f:g} of the stroke: real-time error {max(push['realtime_error_mm']):.2f} mm "
         f"(linear {max(err_rt) * 1e3:.2f} mm), linear on the reference "
         f"mesh {max(err_lin) * 1e3:.2f} mm, last refinement {last} mm")
    return push


def _realtime_summary(rt, snap, timing: dict, timing_sn: dict | None, pushes: list[dict], depths, law: str) -> dict:
    """The summary's ``realtime``: what the node serves (the table, else the linear model) and the linear model."""
    err_rt_all = max(max(p["realtime_error_mm"]) for p in pushes)
    reaches_50 = bool(depths[-1] >= 0.05 - 1e-9)
    err_by_depth = np.max([p["realtime_error_mm"] for p in pushes], axis=0).tolist()
    lin_all = max(max(p["linear_error_mm"]) for p in pushes)
    linear = {"method": f"linear P{rt.order} capacitance over the stroke path (flexsheet/fem/scene_model.py)",
              "update_ms": timing["median"], "update_ms_p90": timing["p90"],
              "max_visible_error_mm": lin_all,
              "error_mm_by_depth": np.max([p["linear_error_mm"] for p in pushes], axis=0).tolist()}
    if snap is not None:
        which = ("the sphere's nonlinear snapshot table (flexsheet/fem/sphere_snapshots.py" if rt.path_table is None else
                 "the scene's nonlinear path table (flexsheet/fem/path_snapshots.py: linear + correction")
        method = (f"{which}, from the {snap}) for pushes inside it, the linear model elsewhere: what the FEM node "
                  "serves on this scene")
        timing = timing_sn
    else:
        method = linear["method"] + ": what the FEM node serves on this scene"
    return {"method": method, "linear": linear,
            "update_ms": timing["median"], "update_ms_p90": timing["p90"], "n_timed": timing["n"],
            "update_wall_ms": timing["wall_median"], "update_wall_ms_p90": timing["wall_p90"],
            "update_timing": "update_ms: the updating thread's CPU time (time.thread_time) per "
                             "update_finger, pushes at 5 stroke points x 5/20/50 mm; the wall time "
                             "beside it includes preemption on a shared machine",
            "sparse_fallback_share": timing["sparse_share"],
            "max_visible_error_mm_0_50": err_rt_all if reaches_50 else None,
            f"max_visible_error_mm_0_{round(depths[-1] * 1e3)}": err_rt_all,
            "error_mm_by_depth": err_by_depth,
            "depths_m": depths.tolist(), "target_mm": TARGET_MM, "meets_target": err_rt_all <= TARGET_MM,
            "depth_note": None if reaches_50 else (
                f"quick stops at {depths[-1] * 1e3:g} mm (its settings: one {law} level on an 8 mm mesh; "
                "the neo-Hookean one needed minutes per 2.5 mm step beyond 30 mm); "
                "max_visible_error_mm_0_50 needs the full run"),
            "mesh": {"spec": rt.spec.key(), "nodes": rt.n_nodes, "candidates": rt.n_candidates,
                     "precompute_MB": rt.solver.nbytes / 1e6},
            "visible": "rendered surface vertices not held by the support and outside the finger's "
                       "footprint (deformed reference position more than finger radius + 2 mm from the push "
                       "axis)"}


def _reference_summary(sc, st: dict, pushes: list[dict], law: str) -> dict:
    """The summary's ``reference``: the nonlinear reference's model, convergence and finest level."""
    from flexsheet.fem.hyperelastic import SOLVER_VERSION

    fine_lv = pushes[0]["reference_levels"][-1]
    return {"model": f"{law} (compressible), total Lagrangian P2, Newton with load stepping, rigid "
                     f"{sc.finger.contact} capsule finger, full body (flexsheet/fem/hyperelastic.py)",
            "contact": sc.finger.contact,
            "law": sc.material.model, "Jm": sc.material.Jm,
            "solver": SOLVER_VERSION,
            "converged": bool(all(p["reference_converged"] for p in pushes)),
            "criterion": "two or more levels, every Newton solve converged and the last refinement "
                         f"changes the visible surface by <= {TARGET_MM / 2} mm",
            "levels_solved": len(st["levels"]),
            "newton_converged": bool(all(lv["newton_converged"] for p in pushes
                                         for lv in p["reference_levels"])),
            "inverted_elements_by_depth": pushes[0]["reference_levels"][-1]["inverted"],
            "last_refinement_change_mm": max(p["last_refinement_change_mm"] for p in pushes)
            if len(st["levels"]) > 1 else None,
            "finest_h_fine_m": fine_lv["h_fine_m"], "finest_dofs": fine_lv["dofs"]}


def run_scene(scene_path, out_dir: str, quick: bool = True, cache_dir: str | None = None) -> dict:
    """Measure the real-time model of the scene file ``scene_path`` against the nonlinear reference (module
    doc); write ``out_dir``/summary.json and the accuracy-against-speed chart; return the summary dict.
    ``cache_dir``: the FEM cache (None: the default, ~/.cache/flexsheet/fem). Raises ``ValueError`` (via
    :class:`flexsheet.model.scenes.SceneError`) for a bad scene file."""
    from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
    from flexsheet.fem.scene_model import SceneModel
    from flexsheet.model.scenes import load_scene

    t0 = time.perf_counter()
    st = QUICK if quick else FULL
    sc = load_scene(scene_path)
    law = f"Gent (Jm {sc.material.Jm:g})" if sc.material.model == "gent" else "neo-Hookean"
    cache_dir = cache_dir or DEFAULT_CACHE_DIR
    cache = ArrayCache(cache_dir, _log)
    os.makedirs(out_dir, exist_ok=True)
    _log(f"scene {sc.name!r} ({sc.source}), {'quick' if quick else 'full'} settings")
    rt = SceneModel(sc, cache_dir=cache_dir, log=_log)
    timing = _update_ms(rt, sc, (0.005, 0.02, 0.05), st["n_time"])
    _log(f"real-time update (linear): CPU median {timing['median']:.3f} ms, p90 {timing['p90']:.3f} ms (wall median "
         f"{timing['wall_median']:.3f} ms)")
    snap = _attach_table(sc, rt, cache)
    timing_sn = None
    if snap is not None:
        timing_sn = _update_ms(rt, sc, (0.005, 0.02, 0.05), st["n_time"])
        _log(f"the node's nonlinear table (from the {snap}): update CPU median {timing_sn['median']:.3f} ms")
    verts = rt.rest_vertices.astype(float)
    held = rt.held
    depths = np.asarray(st["depths"], float)
    pushes = [_scene_push(sc, rt, snap, st, verts, held, cache, f, depths) for f in st["fractions"]]
    summary = {
        "scene": {"name": sc.name, "file": str(sc.source), "kind": sc.object.kind, "key": sc.key(),
                  "description": sc.description},
        "settings": {"quick": quick, **{k: list(v) if isinstance(v, tuple) else v for k, v in st.items()}},
        "realtime": _realtime_summary(rt, snap, timing, timing_sn, pushes, depths, law),
        "reference": _reference_summary(sc, st, pushes, law),
        "linear_fine": {"model": "linear P2 on the finest reference mesh, full sparse solve",
                        "max_visible_error_mm": max(max(p["linear_fine_error_mm"]) for p in pushes),
                        "solve_ms": float(np.median([p["linear_fine_solve_ms"] for p in pushes]))},
        "pushes": pushes,
        "seconds": time.perf_counter() - t0,
    }
    with open(os.path.join(out_dir, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    _plot(out_dir, summary)
    _log(f"done in {summary['seconds']:.0f} s -> {out_dir}")
    return summary


def _plot(out_dir: str, s: dict) -> None:
    """``accuracy_speed_<scene>.png`` + ``.json``: error against update time per model, error against depth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = s["scene"]["name"]
    law = s["reference"]["model"].split(" (compressible)")[0]
    ref_ms = [1e3 * lv["seconds"] / max(1, len(s["realtime"]["depths_m"]))
              for p in s["pushes"] for lv in p["reference_levels"][-1:]]
    lin = s["realtime"]["linear"]
    served_table = any(m in ("snapshots", "path_snapshots") for p in s["pushes"] for m in p["realtime_methods"])
    pts = ([{"model": "real-time nonlinear snapshot table (served)", "update_ms": s["realtime"]["update_ms"],
             "max_visible_error_mm": max(s["realtime"]["error_mm_by_depth"])}] if served_table else []) + [
           {"model": "real-time linear P2 (capacitance)", "update_ms": lin["update_ms"],
            "max_visible_error_mm": lin["max_visible_error_mm"]},
           {"model": "linear P2, reference mesh (sparse)", "update_ms": s["linear_fine"]["solve_ms"],
            "max_visible_error_mm": s["linear_fine"]["max_visible_error_mm"]},
           {"model": f"{law} reference (per depth): its last refinement's change" if
            s["reference"]["last_refinement_change_mm"] is not None else
            f"{law} reference (per depth): 0 by definition, one level, convergence not shown",
            "update_ms": float(np.median(ref_ms)),
            "max_visible_error_mm": s["reference"]["last_refinement_change_mm"] or 0.0}]
    data = {"scene": name, "points": pts, "target_mm": TARGET_MM, "depths_m": s["realtime"]["depths_m"],
            "realtime_error_mm_by_depth": s["realtime"]["error_mm_by_depth"],
            "linear_error_mm_by_depth": lin["error_mm_by_depth"],
            "linear_fine_error_mm_by_depth": np.max([p["linear_fine_error_mm"] for p in s["pushes"]], axis=0).tolist(),
            "note": "the reference's 'error' is its last mesh refinement's change (convergence), not an error"}
    with open(os.path.join(out_dir, f"accuracy_speed_{name}.json"), "w") as fh:
        json.dump(data, fh, indent=1)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 5.6))
    for p, mk in zip(pts, ("D", "o", "s", "^")[-len(pts):], strict=True):
        a1.scatter(p["update_ms"], p["max_visible_error_mm"], marker=mk, s=60, label=p["model"])
    a1.axhline(TARGET_MM, color="k", ls="--", lw=0.8, label="0.7 mm (one projector pixel)")
    a1.axvline(1.0, color="gray", ls=":", lw=0.8, label="1 ms (1 kHz)")
    a1.set_xscale("log")
    a1.set_xlabel("time per update, ms (log)")
    a1.set_ylabel(f"largest visible-surface error 0-{s['realtime']['depths_m'][-1] * 1e3:g} mm, mm")
    a1.set_title(f"{name}: accuracy against speed")
    a1.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.16))       # below: the points stay visible
    d = np.asarray(data["depths_m"]) * 1e3
    if served_table:
        a2.plot(d, data["realtime_error_mm_by_depth"], "D-", label="real-time nonlinear table (served)")
    a2.plot(d, data["linear_error_mm_by_depth"], "o-", label="real-time linear P2")
    a2.plot(d, data["linear_fine_error_mm_by_depth"], "s-", label="linear P2 on the reference mesh")
    a2.axhline(TARGET_MM, color="k", ls="--", lw=0.8)
    a2.set_xlabel("push depth, mm")
    a2.set_ylabel("error against the nonlinear reference, mm")
    a2.set_title(f"{name}: where linear breaks (by depth)")
    a2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, f"accuracy_speed_{name}.png"), dpi=110)
    plt.close(fig)


def compliance_along_stroke(run_dir: str, scene_path, out_dir: str, bin_mm: float = 2.5) -> dict:
    """From a launch run (``run_dir``/sim.mcap): the FEM's dF/dd (``/object/deformation``, valid, depth > 0)
    and the sheet's tension and requested stiffness (``/sheet/target`` while touching) binned by the contact
    point's position along the scene's stroke (arc length, mm; nearest of 400 path points), with each
    inclusion's place on the path (the path point nearest its centre). Writes
    ``fem_compliance_<scene>.png`` + ``.json`` into ``out_dir``; returns the numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.spatial import cKDTree

    from flexsheet.model.scenes import load_scene
    from flexsheet.runtime.bag import read_bag
    from flexsheet.runtime.codec import decode_any

    sc = load_scene(scene_path)
    bag = os.path.join(run_dir, "sim.mcap")
    pts, _ = sc.stroke_points(400)
    s_path = np.linspace(0.0, sc.stroke_length(), 400) * 1e3
    tree = cKDTree(pts)
    de = [m for m in (decode_any(x.frames) for x in read_bag(bag, topics=["/object/deformation"]))
          if m.valid and m.depth > 0 and m.scene_key == sc.key()]
    tg = [m for m in (decode_any(x.frames) for x in read_bag(bag, topics=["/sheet/target"]))
          if m.touching and not m.status.startswith("hold")]
    edges = np.arange(0.0, s_path[-1] + bin_mm, bin_mm)

    def binned(cp, v):
        if not len(cp):
            return [], []
        s = s_path[tree.query(np.asarray(cp))[1]]
        k = np.digitize(s, edges) - 1
        cen, med = [], []
        for b in range(len(edges) - 1):
            sel = k == b
            if sel.sum() >= 3:
                cen.append(float(0.5 * (edges[b] + edges[b + 1])))
                med.append(float(np.median(np.asarray(v)[sel])))
        return cen, med

    out = {"scene": sc.name, "run": run_dir, "bin_mm": bin_mm, "n_deformations": len(de), "n_targets": len(tg),
           "fem_stiffness_N_per_m": binned([m.contact_point for m in de], [m.stiffness for m in de]),
           "fem_depth_mm": binned([m.contact_point for m in de], [m.depth * 1e3 for m in de]),
           "tension_N_per_m": binned([m.contact_point for m in tg], [m.tension for m in tg]),
           "requested_stiffness_N_per_m": binned([m.contact_point for m in tg], [m.object_stiffness for m in tg]),
           "inclusions_at_mm": [float(s_path[tree.query(np.asarray(i.center))[1]]) for i in sc.inclusions]}
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, f"fem_compliance_{sc.name}.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    fig, ax = plt.subplots(figsize=(8, 4.2))
    ax.plot(*out["fem_stiffness_N_per_m"], "o-", label="FEM dF/dd (N/m)")
    ax.plot(*out["tension_N_per_m"], "s-", label="sheet tension (N/m)")
    ax.plot(*out["requested_stiffness_N_per_m"], "^-", label="stiffness asked of the sheet (N/m)")
    for i, x in enumerate(out["inclusions_at_mm"]):
        ax.axvline(x, color="r", ls="--", lw=0.8, label="inclusion centre (nearest path point)" if i == 0 else None)
    ax.set_xlabel("position along the stroke, mm")
    ax.set_ylabel("N/m")
    ax.set_title(f"{sc.name}: FEM stiffness and sheet tension along the stroke (medians per {bin_mm:g} mm)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, f"fem_compliance_{sc.name}.png"), dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    """CLI (see the module doc)."""
    ap = argparse.ArgumentParser(
        prog="python -m flexsheet.experiments.fem_scene",
        description="FEM accuracy (against the nonlinear reference) and speed on one scene.",
        epilog="example: python -m flexsheet.experiments.fem_scene --scene launch/scenes/sphere.yaml --quick "
               "--out out/fem_sphere")
    ap.add_argument("--scene", required=True, help="scene file (launch/scenes/*.yaml)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--quick", action="store_true", help="one push point, two reference levels")
    ap.add_argument("--run", help="instead: chart the FEM stiffness and sheet tension along the stroke from "
                                  "this launch output folder (its sim.mcap)")
    args = ap.parse_args(argv)
    if args.run:
        c = compliance_along_stroke(args.run, args.scene, args.out)
        print(json.dumps(c, indent=1)[:3000])
        return 0
    try:
        s = run_scene(args.scene, args.out, args.quick)
    except ValueError as exc:
        print(f"fem_scene: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({k: s[k] for k in ("scene", "realtime", "reference")}, indent=1, default=str)[:3000])
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
