"""One-off (session 29): is a scene's path-table reference converged? The middle station of
``docs/figures/scenes/NAME/path_table/path_table.json`` pushed again one mesh level finer (h_fine 4 mm instead
of 6 mm, :data:`flexsheet.experiments.path_table.CHECK_H_FINE`, what ``--mesh-check`` solves, without
re-solving the table's other stations) and compared with its 6 mm push over the visible rendered vertices
(not held, outside the finger's footprint), depth by depth; and each held-out push of path_table.json solved at
4 mm too, against what the FEM node serves there (the shipped table: the linear solve plus the moved, blended
6 mm corrections) and against the linear model alone, beside the table's error against the 6 mm held-out push
that path_table.json reports. Writes ``docs/figures/scenes/NAME/mesh_check/mesh_check.json``.

Run from the repository root: ``python3 docs/figures/scenes/mesh_check.py organ`` (cold: the four 4 mm pushes and the 6 mm one
in two worker processes, ~20 min of CPU for each 4 mm push; seconds cached)."""

import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, ".")


def main() -> int:
    from flexsheet.experiments import path_table as P
    from flexsheet.experiments.fem_scene import visible_errors
    from flexsheet.model.scenes import load_scene
    from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache
    from nodes.fem.scene_model import SceneModel, attach_scene_table, finger_on_scene

    name = sys.argv[1] if len(sys.argv) > 1 else "organ"
    here = os.path.join("docs", "figures", "scenes", name)
    scene = os.path.join("launch", "scenes", f"{name}.yaml")
    rep = json.load(open(os.path.join(here, "path_table", "path_table.json")))
    fr = np.asarray([s["fraction"] for s in rep["stations"]])
    f = float(fr[len(fr) // 2])
    t0 = time.perf_counter()
    held_out = [h["fraction"] for h in rep["held_out"]]
    P._prefetch(scene, [(f, P.GRID["h_fine"]), (f, P.CHECK_H_FINE)] + [(h, P.CHECK_H_FINE) for h in held_out],
                DEFAULT_CACHE_DIR, 2)
    sc = load_scene(scene)
    rt = SceneModel(sc)
    cache = ArrayCache(DEFAULT_CACHE_DIR)
    verts = rt.rest_vertices.astype(float)
    held = rt.held
    depths = np.asarray(rep["depths_m"])
    nd = len(depths)
    a = P._push(sc, f, P.GRID["h_fine"], verts, cache)
    b = P._push(sc, f, P.CHECK_H_FINE, verts, cache)
    q, n = sc.stroke_at([f])
    ch = visible_errors(np.asarray(a["u"])[:nd], np.asarray(b["u"])[:nd], verts, held, q[0], n[0], depths,
                        sc.finger.radius)
    within = 0.0
    for d, e in zip(depths, ch, strict=True):
        if e > P.TARGET_MM:
            break
        within = float(d * 1e3)
    _, where = attach_scene_table(rt, cache)
    rows = []
    for h, rh in zip(held_out, rep["held_out"], strict=True):
        fine = P._push(sc, h, P.CHECK_H_FINE, verts, cache)
        qh, nh = sc.stroke_at([h])
        qh, nh = qh[0], nh[0]
        u_ref = np.asarray(fine["u"])[:nd]
        u_tab = np.stack([rt.update_finger(finger_on_scene(qh, nh, float(d), sc.finger.radius)).vertices.astype(float)
                          - verts for d in depths])
        u_lin = P._linear(rt, sc, qh, nh, depths)[0]
        e_tab = visible_errors(u_tab, u_ref, verts, held, qh, nh, depths, sc.finger.radius)
        e_lin = visible_errors(u_lin, u_ref, verts, held, qh, nh, depths, sc.finger.radius)
        rows.append({"fraction": h, "dofs": int(fine["dofs"]), "cpu_seconds": float(fine["seconds"]),
                     "newton_converged": bool(np.all(np.asarray(fine["converged"])[:nd])),
                     "force_N": np.asarray(fine["force"])[:nd].tolist(),
                     "table_vs_fine_mm": e_tab, "linear_vs_fine_mm": e_lin,
                     "table_vs_own_6mm_mm": rh["table_error_mm"]})
        print(f"held out {h:.4g}: the table against the 4 mm push {max(e_tab):.2f} mm (against the 6 mm one "
              f"{rh['table_max_mm']:.2f} mm), linear {max(e_lin):.2f} mm", file=sys.stderr)
    out = {"what": "the middle station's push on the table's mesh (h_fine 6 mm) against the same push one level "
                   "finer (h_fine 4 mm): the largest visible difference per depth (mm), i.e. how far the table's "
                   "reference is from converged there", "scene": name, "fraction": f,
           "depths_m": depths.tolist(), "target_mm": P.TARGET_MM,
           "levels": [{"h_fine_m": P.GRID["h_fine"], "dofs": int(a["dofs"]), "cpu_seconds": float(a["seconds"]),
                       "newton_converged": bool(np.all(np.asarray(a["converged"])[:nd])),
                       "force_N": np.asarray(a["force"])[:nd].tolist()},
                      {"h_fine_m": P.CHECK_H_FINE, "dofs": int(b["dofs"]), "cpu_seconds": float(b["seconds"]),
                       "newton_converged": bool(np.all(np.asarray(b["converged"])[:nd])),
                       "force_N": np.asarray(b["force"])[:nd].tolist()}],
           "table_from": where, "held_out_fine": rows,
           "change_mm": ch, "max_change_mm": max(ch), "within_target_to_mm": within,
           "wall_seconds": time.perf_counter() - t0}
    os.makedirs(os.path.join(here, "mesh_check"), exist_ok=True)
    with open(os.path.join(here, "mesh_check", "mesh_check.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    print(f"{name} at {f:.4g}: 6 -> 4 mm moves the visible surface by {max(ch):.2f} mm at most; within "
          f"{P.TARGET_MM} mm to {within:g} mm", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
