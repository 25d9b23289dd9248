"""The fold study (``--fold-study``, ``fold_study.json``, :func:`fold_study`): does the reference fold its own
surface, and is that where it does not converge?"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.experiments.fem.studies.fold_check import FOLD_REGION, fold_path, fold_path_json
from flexsheet.experiments.fem.studies.tip import tip_sequence
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.fold import CREASE_STRETCH_RATIO
from flexsheet.fem.reference.paths import at_depths, push_depths, reference_path
from flexsheet.fem.reference.settings import Settings
from flexsheet.fem.visible_error import visible_diffs, visible_vertices


def _where_worst(a: dict, b: dict, j: int, depth: float, verts: np.ndarray, fixed: np.ndarray, mesh) -> dict:
    """Where the largest visible difference between paths ``a`` and ``b`` (D, k, 3) m at row ``j`` sits: its
    rendered vertex's rest distance from the push axis (azimuth 0) and its motion along the push on ``b``
    (mm)."""
    vis = visible_vertices(verts + b["u"][j], fixed, 0.0, depth, mesh)
    dist = np.linalg.norm(a["u"][j] - b["u"][j], axis=1)
    i = int(np.flatnonzero(vis)[np.argmax(dist[vis])])
    rel = verts[i] - mesh.center
    return {"lateral_mm": float(math.hypot(rel[1], rel[2]) * 1e3), "drop_mm": float(-b["u"][j][i][0] * 1e3),
            "difference_mm": float(dist[i] * 1e3)}


def fold_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Does the reference fold its own surface, and is that where it does not converge? The last three
    convergence levels (quick: its two) pushed at azimuth 0 (their loading paths, as :func:`convergence` reads
    them): per level and depth the :func:`fold_path` figures, the visible-surface difference to the finest
    level and where the largest one sits (rest distance from the push axis, drop along the push).
    "fold_free_to_mm": on the finest level, the deepest depth to which no surface point lies inside the body
    (the reference is a solution of the modelled problem there; past it the model lacks the self-contact the
    folding surface needs); "tip_sequence" (:func:`tip_sequence`). Returns {"depths_mm", "region_mm", "levels"
    (per level: "h_fine_mm", "dofs", :func:`fold_path_json`'s keys, "force_N", and for the coarser ones
    "difference_to_finest_mm" and "worst_difference_at" [{"lateral_mm", "drop_mm", "difference_mm"}]),
    "tip_sequence", "fold_free_to_mm", "first_penetration_mm_by_h_fine_mm", "crease_stretch_ratio", "what"};
    lengths in mm. Raises ``RuntimeError`` as :func:`fold_path`."""
    depths = push_depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    lv = st.levels[-3:]
    fdepths = push_depths(st.fine_step)
    fine = at_depths(reference_path(lv[-1], 0.0, fdepths, mat, cache, verts, st.contact), fdepths, depths)
    rows = []
    for i, s in enumerate(lv):
        p = fine if i == len(lv) - 1 else reference_path(s, 0.0, depths, mat, cache, verts, st.contact)
        f = fold_path(s, 0.0, p, depths, mat, cache)
        row = {"h_fine_mm": s.h_fine * 1e3, "dofs": int(p["dofs"]), **fold_path_json(f),
               "force_N": p["force"].tolist()}
        if i < len(lv) - 1:
            row["difference_to_finest_mm"] = [e * 1e3
                                              for e in visible_diffs(p, fine, depths, verts, fixed, rm.mesh)]
            row["worst_difference_at"] = [_where_worst(p, fine, j, d, verts, fixed, rm.mesh)
                                          for j, d in enumerate(depths)]
        rows.append(row)
    tip = tip_sequence(st, mat, cache, rm, fine)
    pen = np.asarray(rows[-1]["n_penetrating"]) > 0
    free = float(depths[np.argmax(pen) - 1] * 1e3) if pen.any() and pen.argmax() > 0 else \
        (0.0 if pen.any() else float(depths[-1] * 1e3))
    first = {r["h_fine_mm"]: (float(depths[np.argmax(np.asarray(r["n_penetrating"]) > 0)] * 1e3)
                              if np.any(np.asarray(r["n_penetrating"]) > 0) else None) for r in rows}
    return {"depths_mm": (depths * 1e3).tolist(), "region_mm": FOLD_REGION * 1e3, "levels": rows,
            "tip_sequence": tip, "fold_free_to_mm": free, "first_penetration_mm_by_h_fine_mm": first,
            "crease_stretch_ratio": CREASE_STRETCH_RATIO,
            "what": "self-contact and crease check of the reference at azimuth 0 "
                    "(flexsheet/fem/reference/fold.py): the "
                    "generalised winding number w of the closed outer surface at its own points within "
                    f"{FOLD_REGION * 1e3:g} mm (rest) of the push axis, off the finger's footprint: 0.5 on a "
                    "smooth surface, alpha/2pi at the bottom of a fold of interior angle alpha, > 1 where "
                    "the point lies inside the body (the surface has passed through itself: the model has no "
                    "self-contact); max_penetration_mm how deep; min_stretch_ratio the smallest in-plane "
                    "stretch of the surface triangles off the footprint (a neo-Hookean surface creases below "
                    "~0.65)"}
