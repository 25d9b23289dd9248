"""The FEM's accuracy and speed on any scene, as the user's eyes see it: ``flexsheet experiment fem --quick
--scene launch/scenes/NAME.yaml`` (wired by :mod:`flexsheet.experiments.fem`; the paper's cylinder too, into
``--out``/visible/ of its own quick run) calls :func:`run_scene`.

What it measures, for the model the FEM node serves for the scene (:func:`flexsheet.fem.served.served_model`):

1. **Update time**: thread CPU time of one ``update_finger`` at pushes along the stroke, median and p90, ms.
2. **What the eyes see against the reference** (:mod:`flexsheet.fem.eye_judge`): at the stroke's middle (full:
   its start, middle and end), a rigid capsule finger pushed along the inward normal every 5 mm over the
   scene's declared range (``use.max_depth``) into the scene's compressible hyperelastic body (its law, its
   contact law, its support and inclusions: total Lagrangian P2, Newton with load stepping,
   :mod:`flexsheet.fem.reference.hyperelastic`), on gmsh meshes refined along the whole push path and on the
   support's rim. **Shape** (each seen vertex's distance to the reference's surface, and each eye's outline)
   is judged, **sliding** along the surface reported beside it, in projector pixels. Linear P2 on the
   reference's own mesh is judged too.
3. **The reference's band**: three levels (h_fine 8, 6, 4.5 mm: ratio 4/3) give the finest level's grid
   convergence index per depth (:mod:`flexsheet.fem.reference.gci`); where it holds (≤ 0.5 px) only part of
   the way, ``visible.converged_to_mm`` (never under 15 mm) with the error there and the band beyond.
4. **What the eye notices as the finger moves** (:mod:`flexsheet.experiments.fem_motion`): the drawn dent
   against the fingertip (``contact``) and frame-to-frame jumps (``temporal``) along the stroke and the push.

Outputs in ``out_dir``: ``summary.json`` (``scene`` with ``max_depth_mm`` and ``contact``,
``realtime.update_ms``, ``visible.shape_px_max``, ``visible.sliding_px_max``, ``reference.gci_px``,
``contact.gap_px_max``, ``temporal.jump_px_p99``, the pushes) and ``accuracy_<name>.png`` + ``.json``.
Reference solves are cached (:class:`flexsheet.fem.cache.ArrayCache`, the key includes ``scene.key()``),
solved first on dask when the cache lacks them (:func:`flexsheet.fem.reference.workers.run_workers`).
:func:`flexsheet.fem.eye_judge.shape_px_by_depth` is the same shape metric for the sphere and path tables'
held-out and mesh checks.

Run by hand::

    python -m flexsheet.experiments.fem_scene --scene launch/scenes/sphere.yaml --quick --out docs/figures/scenes/sphere
"""  # noqa: E501 - a table, template or command line kept whole

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time

import numpy as np

from flexsheet.experiments.fem_motion import served_motion
from flexsheet.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
from flexsheet.fem.config import FemConfig
from flexsheet.fem.eye_judge import judge
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import TetMesh, surface_faces
from flexsheet.fem.reference.gci import gci_by_depth
from flexsheet.fem.reference.scene_reference import FULL, QUICK, scene_reference
from flexsheet.fem.reference.workers import parallel, run_workers
from flexsheet.fem.scene_model import finger_on_scene
from flexsheet.fem.served import launch_arc_deg, scene_update_ms, served_finger, served_model
from flexsheet.fem.solver import FemModel, solve_full
from flexsheet.model.scenes import load_scene
from flexsheet.runtime.console import LIBRARY, show_lines

log = logging.getLogger("flexsheet.experiments.fem_scene")   # also when run as __main__

__all__ = ["run_scene", "main", "TARGET_MM", "TARGET_PX", "CONVERGED_PX"]

TARGET_MM = 0.7                      #: one projector pixel on the screen, mm
TARGET_PX = 1.0                      #: the served model's largest visible error, projector px
CONVERGED_PX = 0.5                   #: a reference counts as converged where two levels differ by this, px
DEPTH_STEP = 0.005                   #: the judged depths: every 5 mm to the scene's use.max_depth, m
def _linear_fine(sc, ref: dict, q, n, depths, probes) -> tuple[np.ndarray, float]:
    """Linear P2 on the reference's mesh (full sparse solve): displacements (D, k, 3) at ``probes`` and the
    median solve time, ms."""
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


def _ref_job(args: tuple) -> tuple[float, float, str | None]:
    """Worker (:func:`flexsheet.fem.reference.workers.run_workers`): one reference level of one push into the
    cache; (h_fine, seconds, None or the error)."""
    scene_file, f, h, st, probes, cache_dir = args

    t = time.perf_counter()
    try:
        sc = load_scene(scene_file)
        q, n = sc.stroke_at([f])
        scene_reference(sc, q[0], n[0], h, st, probes, ArrayCache(cache_dir))
    except Exception as exc:                    # noqa: BLE001 - reported; the run solves it again and raises
        return h, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"
    return h, time.perf_counter() - t, None


def _scene_push(sc, rt, st: dict, verts, faces, cache, f: float, depths) -> dict:
    """One push point (fraction ``f`` of the stroke): the reference's levels, the served model and linear P2
    on the finest level's mesh, each judged by the eyes against the finest level (px,
    :func:`flexsheet.fem.eye_judge.judge`: shape, silhouette and sliding), and each level against the next
    finer one (shape and silhouette, for the convergence index)."""
    q, n = sc.stroke_at([f])
    q, n = q[0], n[0]
    refs = [scene_reference(sc, q, n, h, st, verts, cache) for h in st["levels"]]
    fine = refs[-1]
    fingers = [served_finger(sc, q, n, float(d)) for d in depths]
    ups = [rt.update_finger(fg) for fg in fingers]
    lin_u, lin_ms = _linear_fine(sc, fine, q, n, depths, verts)
    rows = {k: [] for k in ("served_shape_px", "served_silhouette_px", "served_sliding_px", "served_total_px",
                            "linear_fine_px", "seen_vertices")}
    changes = [[] for _ in refs[:-1]]            # level i against level i+1, fine last
    for j, fg in enumerate(fingers):
        (sv, li), k = judge([np.asarray(ups[j].vertices, float), verts + lin_u[j]], verts + fine["u"][j],
                            faces, fg)
        for key, v in (("served_shape_px", sv["shape_px"]), ("served_silhouette_px", sv["silhouette_px"]),
                       ("served_sliding_px", sv["sliding_px"]), ("served_total_px", sv["total_px"]),
                       ("linear_fine_px", max(li["shape_px"], li["silhouette_px"])), ("seen_vertices", k)):
            rows[key].append(v)
        for i in range(len(refs) - 1):
            (c,), _ = judge([verts + refs[i]["u"][j]], verts + refs[i + 1]["u"][j], faces, fg)
            changes[i].append(max(c["shape_px"], c["silhouette_px"]))
    levels = [{"h_fine_m": h, "dofs": int(r["dofs"]), "seconds": float(r["seconds"]),
               "newton_converged": bool(np.all(r["converged"])), "force_N": r["force"].tolist(),
               "inverted": r["inverted"].tolist()} for h, r in zip(st["levels"], refs, strict=True)]
    shape = np.maximum(rows["served_shape_px"], rows["served_silhouette_px"])
    push = {"fraction": f, "point_m": q.tolist(), "normal": n.tolist(), "depths_m": depths.tolist(), **rows,
            "served_px": shape.tolist(), "served_methods": sorted({u.method for u in ups}),
            "served_force_N": [u.force for u in ups], "served_stiffness_N_per_m": [u.stiffness for u in ups],
            "linear_fine_solve_ms": lin_ms, "reference_levels": levels, "level_change_px": changes}
    log.info(f"push at {f:g} of the stroke: served shape {shape.max():.2f} px (sliding "
             f"{max(rows['served_sliding_px']):.2f} px), linear on the reference mesh "
             f"{max(rows['linear_fine_px']):.2f} px"
             + (f", last refinement {max(changes[-1]):.2f} px" if changes else ""))
    return push


def judged_range(depths: np.ndarray, band: np.ndarray | None) -> float | None:
    """The deepest depth (m) up to which the reference's band (px: its grid convergence index, or with two
    levels their difference) is ≤ :data:`CONVERGED_PX` at every judged depth (the range a served figure is
    judged over when the reference does not converge over the scene's whole range); None without a band or
    when it holds nowhere up to 15 mm, the least judged range the scenes may have."""
    if band is None:
        return None
    ok = np.asarray(band, float) <= CONVERGED_PX
    n = int(np.argmin(ok)) if not ok.all() else len(ok)
    if n == 0 or depths[n - 1] < 0.015 - 1e-9:
        return None
    return float(depths[n - 1])


def run_scene(scene_path, out_dir: str, quick: bool = True, cache_dir: str | None = None, jobs: int = 1,
              levels: tuple[float, ...] | None = None) -> dict:
    """Judge the model the FEM node serves for the scene file ``scene_path``
    (:func:`flexsheet.fem.served.served_model`) against the scene's nonlinear reference, as the eyes see it
    (module doc), over the scene's declared depths (``use.max_depth``); write ``out_dir``/summary.json and the
    accuracy chart; return the summary. The reference levels the cache lacks are solved first on dask
    (``jobs`` local processes or the ``--scheduler``'s cluster,
    :func:`flexsheet.fem.reference.workers.run_workers`). ``cache_dir``: the FEM cache (None:
    ~/.cache/flexsheet/fem). ``levels``: the reference levels' h_fine (m, coarse to fine; default the
    settings'). Raises ``ValueError`` (:class:`flexsheet.model.scene_parts.SceneError`) for a bad scene
    file."""
    t0 = time.perf_counter()
    sc = load_scene(scene_path)
    st = _scene_settings(sc, quick, levels)
    depths = np.asarray(st["depths"], float)
    cache_dir = cache_dir or DEFAULT_CACHE_DIR
    cache = ArrayCache(cache_dir)
    os.makedirs(out_dir, exist_ok=True)
    log.info(f"scene {sc.name!r} ({sc.source}), {'quick' if quick else 'full'}: pushes 0-{depths[-1] * 1e3:g}"
         f" mm ({sc.use.reason or 'no reason given'}), {sc.finger.contact} contact")
    rt, what = served_model(sc, FemConfig(arc_deg=launch_arc_deg(sc)), cache_dir=cache_dir)
    log.info(f"served model: {what}")
    timing = scene_update_ms(rt, sc, (0.005, depths[len(depths) // 2], depths[-1]), st["n_time"])
    log.info(f"update: CPU median {timing['median']:.3f} ms, p90 {timing['p90']:.3f} ms")
    verts = rt.rest_vertices.astype(float)
    faces = np.asarray(rt.faces)
    _solve_references(scene_path, st, verts, cache_dir, jobs)
    pushes = [_scene_push(sc, rt, st, verts, faces, cache, f, depths) for f in st["fractions"]]
    summary = _summary(sc, quick, st, what, timing, pushes, served_motion(sc, rt), t0)
    served = np.asarray(summary["visible"]["px_by_depth"])
    with open(os.path.join(out_dir, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    _plot(out_dir, summary)
    log.info(f"done in {summary['seconds']:.0f} s -> {out_dir}: shape {served.max():.2f} px (target "
             f"{TARGET_PX}), "
             f"reference GCI {summary['reference']['gci_px']} px (target {CONVERGED_PX}), contact gap "
             f"{summary['contact']['gap_px_max']:.2f} px, jump p99 {summary['temporal']['jump_px_p99']:.2f} "
             "px")
    return summary


def _scene_settings(sc, quick: bool, levels: tuple[float, ...] | None) -> dict:
    """:data:`~flexsheet.fem.reference.scene_reference.QUICK` or ``FULL`` for scene ``sc``: the reference
    ``levels`` (h_fine m) when given, and the push depths every :data:`DEPTH_STEP` m up to the scene's
    declared ``use.max_depth`` (never past it)."""
    st = dict(QUICK if quick else FULL)
    if levels is not None:
        st["levels"] = tuple(levels)
    n_d = int(sc.use.max_depth / DEPTH_STEP + 1e-9)         # never past the declared range
    st["depths"] = tuple(np.round(np.arange(1, n_d + 1) * DEPTH_STEP, 9))
    if st["path_depth"] is True:  # refined along the whole push, to the declared depth
        st["path_depth"] = float(sc.use.max_depth)
    return st


def _solve_references(scene_path, st: dict, verts: np.ndarray, cache_dir: str, jobs: int) -> None:
    """Solve every reference level of every push of ``st`` the cache lacks in ``jobs`` worker processes
    (:func:`flexsheet.fem.reference.workers.run_workers`), sampled at the rendered vertices ``verts`` (S, 3)
    m; with one local worker (and no cluster) nothing here: the pushes are solved as they are read."""
    work = [(str(scene_path), f, h, st, verts, cache_dir) for f in st["fractions"] for h in st["levels"]]
    if parallel(jobs) and len(work) > 1:
        for h, sec, err in run_workers(_ref_job, work, min(jobs, len(work))):
            log.info(f"reference level {h * 1e3:g} mm: {'failed: ' + err if err else 'done'} ({sec:.0f} s)")


def _band(st: dict, pushes: list[dict]) -> dict:
    """The reference's band per depth, px: with three levels the fine level's grid convergence index
    (:func:`flexsheet.fem.reference.gci.gci_by_depth`) of the levels' visible shape differences; with two,
    their difference."""
    ch = [np.max([p["level_change_px"][i] for p in pushes], axis=0) for i in range(len(st["levels"]) - 1)]
    if len(ch) >= 2:
        g = gci_by_depth(ch[-1], ch[-2], tuple(st["levels"][-3:]))
        return {"band": np.asarray(g["gci_px"]), "order": g["order"], "ratios": g["ratios"],
                "changes": [c.tolist() for c in ch], "kind": "gci"}
    return {"band": ch[0] if ch else None, "order": None, "ratios": None,
            "changes": [c.tolist() for c in ch], "kind": "difference of two levels" if ch else None}


def _summary(sc, quick: bool, st: dict, what: str, timing: dict, pushes: list[dict], motion: dict,
             t0: float) -> dict:
    """summary.json of :func:`run_scene`: the scene (its contact law), the served model (``what``) and its
    update ``timing``, what the eyes see of ``pushes`` (:func:`_scene_push`) by depth, the reference's band,
    and the ``motion`` blocks (:func:`flexsheet.experiments.fem_motion.served_motion`); ``t0`` the run's
    start."""
    depths = np.asarray(st["depths"], float)
    mx = {k: np.max([p[k] for p in pushes], axis=0) for k in ("served_shape_px", "served_silhouette_px",
                                                                "served_sliding_px", "served_total_px")}
    served = np.maximum(mx["served_shape_px"], mx["served_silhouette_px"])
    b = _band(st, pushes)
    band = b["band"]
    judged = judged_range(depths, band)
    finite = band is not None and bool(np.all(np.isfinite(band)))
    return {
        "scene": {"name": sc.name, "file": str(sc.source), "kind": sc.object.kind, "key": sc.key(),
                  "description": sc.description, "max_depth_mm": sc.use.max_depth * 1e3,
                  "stroke_depth_mm": sc.use.stroke_depth * 1e3, "reason": sc.use.reason,
                  "contact": sc.finger.contact, "contact_source": sc.finger.contact_source},
        "settings": {"quick": quick, **{k: list(v) if isinstance(v, tuple) else v for k, v in st.items()}},
        "realtime": {"method": what, "update_ms": timing["median"], "update_ms_p90": timing["p90"],
                     "update_wall_ms": timing["wall_median"], "n_timed": timing["n"],
                     "methods": timing["methods"],
                     "target_ms": 1.0, "meets_target": timing["median"] <= 1.0,
                     "update_timing": "the updating thread's CPU time (time.thread_time) per update_finger"},
        "visible": {"shape_px_max": float(served.max()), "range_mm": [0.0, depths[-1] * 1e3],
                    "px_by_depth": served.tolist(), "depths_mm": (depths * 1e3).tolist(),
                    "shape_px_by_depth": mx["served_shape_px"].tolist(),
                    "silhouette_px_by_depth": mx["served_silhouette_px"].tolist(),
                    "sliding_px_by_depth": mx["served_sliding_px"].tolist(),
                    "sliding_px_max": float(mx["served_sliding_px"].max()),
                    "total_px_by_depth": mx["served_total_px"].tolist(),
                    "seen_vertices_by_depth": np.min([p["seen_vertices"] for p in pushes], axis=0).tolist(),
                    "target_px": TARGET_PX, "meets_target": bool(served.max() <= TARGET_PX),
                    "linear_fine_px": float(max(max(p["linear_fine_px"]) for p in pushes)),
                    "converged_to_mm": judged * 1e3 if judged is not None else None,
                    "max_px_in_converged_range": float(served[depths <= judged + 1e-9].max())
                    if judged is not None else None,
                    "band_beyond_px": [float(served[depths > judged + 1e-9].min()),
                                       float(served[depths > judged + 1e-9].max())]
                    if judged is not None and np.any(depths > judged + 1e-9) else None,
                    "metric": "rendered vertices either eye (V -/+ 32 mm along y) sees on the reference's "
                              "deformed surface, the finger an occluding capsule; shape: each served "
                              "vertex's distance to the reference's surface, and the outline's (Hausdorff), "
                              "as the eyes see them on the imaginary screen, px (0.7 mm); sliding along the "
                              "surface reported apart (a texture would show it); flexsheet/fem/eye_judge.py"},
        "reference": {"model": f"{sc.material.model} (compressible, nu {sc.material.nu:g}), total Lagrangian "
                               f"P2, Newton with load stepping, rigid {sc.finger.contact} capsule finger, "
                               "full body",
                      "gci_px": (float(np.max(band)) if finite else (None if band is None else "inf")),
                      "gci_px_by_depth": [None if not np.isfinite(x) else float(x) for x in band]
                      if band is not None else None,
                      "band_kind": b["kind"], "order_by_depth": b["order"], "ratios": b["ratios"],
                      "level_changes_px": b["changes"], "target_px": CONVERGED_PX,
                      "converged_to_mm": judged * 1e3 if judged is not None else None,
                      "converged": bool(finite and np.max(band) <= CONVERGED_PX and all(
                          lv["newton_converged"] for p in pushes for lv in p["reference_levels"])),
                      "levels": pushes[0]["reference_levels"],
                      "criterion": "the finest level's band (GCI of three levels at ratio 4/3, F_s 1.25, "
                                   f"order capped at 2) <= {CONVERGED_PX} px at every depth, every Newton "
                                   "solve converged"},
        **motion,
        "pushes": pushes,
        "seconds": time.perf_counter() - t0,
    }


def _plot(out_dir: str, s: dict) -> None:
    """``accuracy_<scene>.png`` + ``.json``: visible error (px) by depth of the served model, linear P2 on the
    reference mesh and the reference's last refinement, with the targets and verdicts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = s["scene"]["name"]
    v, r = s["visible"], s["reference"]
    data = {"title": f"{name}: visible FEM error as the eyes see it", "units": {"depth": "mm", "error": "px"},
            "depths_mm": v["depths_mm"], "served_px": v["px_by_depth"],
            "sliding_px": v["sliding_px_by_depth"],
            "linear_fine_px": np.max([p["linear_fine_px"] for p in s["pushes"]], axis=0).tolist(),
            "reference_change_px": r["gci_px_by_depth"], "target_px": v["target_px"],
            "converged_target_px": r["target_px"], "update_ms": s["realtime"]["update_ms"],
            "verdict": {"served": "met" if v["meets_target"] else "MISSED",
                        "reference": "met" if r["converged"] else "MISSED"}}
    with open(os.path.join(out_dir, f"accuracy_{name}.json"), "w") as fh:
        json.dump(data, fh, indent=1)
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    ax.plot(data["depths_mm"], data["served_px"], "D-",
            label=f"served model ({s['realtime']['update_ms']:.2f} ms/update): {data['verdict']['served']}")
    ax.plot(data["depths_mm"], data["sliding_px"], "x:", label="served model: sliding (not judged)")
    ax.plot(data["depths_mm"], data["linear_fine_px"], "s-", label="linear P2 on the reference mesh")
    if data["reference_change_px"] is not None:
        ax.plot(data["depths_mm"], [np.nan if x is None else x for x in data["reference_change_px"]], "^--",
                label=f"reference: its band ({r['band_kind']}): {data['verdict']['reference']}")
        ax.axhline(r["target_px"], color="gray", ls=":", lw=0.8, label=f"converged: {r['target_px']} px")
    ax.axhline(v["target_px"], color="k", ls="--", lw=0.8, label=f"target {v['target_px']} px")
    ax.set_xlabel("push depth, mm")
    ax.set_ylabel("largest visible shape error, projector px")
    ax.set_title(data["title"] + f" (0-{v['range_mm'][1]:g} mm, {s['scene']['contact']} contact)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, f"accuracy_{name}.png"), dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """CLI (see the module doc)."""
    ap = argparse.ArgumentParser(
        prog="python -m flexsheet.experiments.fem_scene",
        description="FEM accuracy (against the nonlinear reference) and speed on one scene.",
        epilog="example: python -m flexsheet.experiments.fem_scene --scene launch/scenes/sphere.yaml --quick "
               "--out out/fem_sphere")
    ap.add_argument("--scene", required=True, help="scene file (launch/scenes/*.yaml)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--quick", action="store_true", help="one push point (the stroke's middle), three "
                                                         "reference levels (h_fine 8, 6, 4.5 mm)")
    ap.add_argument("--jobs", type=int, default=1, help="reference levels solved in N worker processes "
                                                        "(default 1)")
    args = ap.parse_args(argv)
    # the library's progress, the worker pool's (flexsheet.fem.reference.workers) included
    show_lines(LIBRARY)
    try:
        s = run_scene(args.scene, args.out, args.quick, jobs=args.jobs)
    except ValueError as exc:
        print(f"fem_scene: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({k: s[k] for k in ("scene", "realtime", "reference")}, indent=1, default=str)[:3000])
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
