"""The reference's mesh convergence at azimuth 0 (:func:`convergence`, ``convergence.json``) and the two
studies written beside it: the contact penalty's convergence (:func:`penalty_study`) and the surface-layer
refinement (:func:`skin_study`)."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.capsule_contact import PENALTY_SCALE
from flexsheet.fem.reference.paths import at_depths, push_depths, reference_path
from flexsheet.fem.reference.settings import PENALTY_TOL_MM, TARGET, Settings
from flexsheet.fem.visible_error import visible_diffs

log = logging.getLogger(__name__)


def sequence_verdict(e: np.ndarray, depths: np.ndarray) -> tuple[bool, float, float]:
    """Mesh-sequence verdict from ``e`` (L-1, D) mm, each coarser level's visible-surface difference to the
    finest at ``depths`` (D,) m: (the difference falls with every refinement at every depth ≥ 5 mm, the last
    refinement's largest change in mm, the deepest depth in mm to which both hold with the last change ≤ half
    the target; 0 with fewer than 3 levels)."""
    deep = depths >= 0.005 - 1e-12
    monotone = bool(np.all(np.diff(e[:, deep], axis=0) < 0)) if len(e) > 1 else False
    last = float(e[-1].max())
    ok = ((e[-1] <= TARGET * 1e3 / 2)
          & (~deep | np.all(np.diff(e, axis=0) < 0, axis=0) if len(e) > 1 else False))
    n_ok = int(np.argmin(ok)) if not np.all(ok) else len(ok)
    return monotone, last, (float(depths[n_ok - 1] * 1e3) if n_ok and len(e) > 1 else 0.0)


def convergence(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> tuple[dict, dict]:
    """Mesh convergence at azimuth 0 on the rendered vertices; returns (report, finest level's path, sampled
    every ``st.fine_step``)."""
    depths = push_depths(st.depth_step)
    fdepths = push_depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    paths = [reference_path(s, 0.0, depths, mat, cache, verts, st.contact) for s in st.levels[:-1]]
    fine = reference_path(st.levels[-1], 0.0, fdepths, mat, cache, verts, st.contact)
    paths.append(at_depths(fine, fdepths, depths))
    rep = {"depths_m": depths.tolist(), "levels": []}
    for s, p in zip(st.levels, paths, strict=True):
        err = visible_diffs(p, paths[-1], depths, verts, fixed, rm.mesh)
        rep["levels"].append({"spec": s.__dict__, "h_fine_m": s.h_fine, "dofs": int(p["dofs"]),
                              "seconds": float(p["seconds"]), "error_vs_finest_mm": [e * 1e3 for e in err],
                              "force_N": p["force"].tolist(), "inverted_nodal": p["inverted"].tolist(),
                              "inverted_qp": p["inverted_qp"].tolist(), "min_detF": p["min_detF"].tolist(),
                              "inverted_nodal_visible": p["inverted_nodal_visible"].tolist(),
                              "max_strain": p["max_strain"].tolist(),
                              "penetration_mm": (p["penetration"] * 1e3).tolist(),
                              "newton_iterations": p["newton"].tolist(),
                              "newton_converged": bool(p["converged"].all()),
                              "cpu_seconds": float(p["cpu_seconds"])})
    e = np.array([lv["error_vs_finest_mm"] for lv in rep["levels"][:-1]])          # (L-1, D)
    deep = depths >= 0.005 - 1e-12
    monotone, last, rep["converged_to_depth_mm"] = sequence_verdict(e, depths)
    no_qp = int(fine["inverted_qp"].max()) == 0
    rep.update({"monotone_decrease": monotone, "last_refinement_change_mm": last,
                "finest_inverted_nodal_at_50mm": int(fine["inverted"][-1]),
                "finest_inverted_nodal_visible_max": int(fine["inverted_nodal_visible"].max()),
                "finest_inverted_qp_at_50mm": int(fine["inverted_qp"][-1]),
                "finest_inverted_qp_max": int(fine["inverted_qp"].max()),
                "finest_newton_converged": bool(fine["converged"].all()),
                "converged": monotone and last <= TARGET * 1e3 / 2 and bool(fine["converged"].all())
                and no_qp,
                "criterion": "at least 3 meshes; the visible-surface difference to the finest mesh falls "
                             "with every refinement (depths >= 5 mm), the last refinement changes it by <= "
                             "half the 0.7 mm target, Newton converged at every load step of the finest "
                             "mesh, and no element of it is inverted at a quadrature point"})
    if len(e) > 1:
        r = st.levels[-3].h_fine / st.levels[-2].h_fine if len(st.levels) >= 3 else 2.0
        with np.errstate(divide="ignore", invalid="ignore"):
            p_obs = np.log(e[-2] / e[-1]) / np.log(r)
        rep["observed_order_median"] = float(np.nanmedian(p_obs[deep]))
    log.info(f"convergence: errors vs finest at 50 mm {[round(float(x[-1]), 3) for x in e]} mm, converged "
             f"{rep['converged']}")
    return rep, fine


def penalty_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Convergence in the contact penalty κ = scale·E/h on one mesh (``st.penalty_level``), azimuth 0: per
    scale the largest visible-surface difference (mm) to the stiffest scale per depth, the deepest penetration
    and the force at 50 mm. ``converged``: the default scale (:data:`PENALTY_SCALE`) lies within
    ``PENALTY_TOL_MM`` of the next 10× stiffer one at every depth (the penalty error is then below the mesh's)
    and Newton converged at every load step of both."""
    depths = push_depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    spec = st.levels[st.penalty_level]
    scales = sorted(st.penalty_scales)
    paths = [reference_path(spec, 0.0, depths, mat, cache, verts, st.contact, sc) for sc in scales]
    rows = [{"penalty_scale": sc,
             "error_vs_stiffest_mm": [e * 1e3
                                      for e in visible_diffs(p, paths[-1], depths, verts, fixed, rm.mesh)],
             "penetration_mm_at_50mm": float(p["penetration"][-1]) * 1e3,
             "penetration_mm_max": float(np.max(p["penetration"])) * 1e3,
             "force_N_at_50mm": float(p["force"][-1]),
             "newton_converged": bool(p["converged"].all()), "cpu_seconds": float(p["cpu_seconds"])}
            for sc, p in zip(scales, paths, strict=True)]
    i = scales.index(PENALTY_SCALE)
    nxt = 10 * PENALTY_SCALE
    if nxt in scales:
        j = scales.index(nxt)
        change = max(visible_diffs(paths[i], paths[j], depths, verts, fixed, rm.mesh)) * 1e3
    else:
        change = float("nan")
    rep = {"mesh": spec.__dict__, "depths_m": depths.tolist(), "default_scale": PENALTY_SCALE, "scales": rows,
           "default_vs_10x_stiffer_mm": change, "tolerance_mm": PENALTY_TOL_MM,
           "converged": bool(change <= PENALTY_TOL_MM and rows[i]["newton_converged"]
                             and (nxt not in scales or rows[scales.index(nxt)]["newton_converged"]))}
    log.info(f"penalty study on h_fine {spec.h_fine * 1e3:g} mm: default vs 10x stiffer {change:.3f} mm, "
             f"penetration at 50 mm {[round(r['penetration_mm_at_50mm'], 3) for r in rows]} mm for {scales}")
    return rep


def skin_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict,
               fine: dict) -> dict:
    """Where the unconverged part of the reference lies: the next-to-finest convergence mesh (full mode: the
    snapshot mesh) with only its surface layer refined (``skin_h`` in ``st.skin_sizes``: the material that
    wraps the fingertip and lines the crater, :class:`flexsheet.fem.reference.mesh.RefSpec`), against the same
    mesh refined throughout its push tube (the finest convergence level). ``conv``: :func:`convergence`'s
    report; ``fine``: its finest path. Per variant the largest visible-surface difference (mm, per depth) to
    the unrefined mesh and to the finest level (visible on the finer of the two, as in :func:`convergence`),
    the force at 50 mm, DOF and CPU, and ``change_vs_previous_mm`` (to the previous, coarser skin; the first:
    to the unrefined mesh); ``tube_change_mm``: the finest level against the unrefined mesh (from ``conv``).
    Azimuth 0, every ``st.depth_step``."""
    depths = push_depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    unrefined = st.levels[-2]
    base = reference_path(unrefined, 0.0, depths, mat, cache, verts, st.contact)
    fine = at_depths(fine, push_depths(st.fine_step), depths)
    rows, prev = [], base
    for h in st.skin_sizes:
        spec = replace(unrefined, skin_h=h)
        p = reference_path(spec, 0.0, depths, mat, cache, verts, st.contact)
        rows.append({"skin_h_m": h, "spec": spec.__dict__, "dofs": int(p["dofs"]),
                     "cpu_seconds": float(p["cpu_seconds"]),
                     "newton_converged": bool(p["converged"].all()), "force_N_at_50mm": float(p["force"][-1]),
                     "change_vs_unrefined_mm": [e * 1e3
                                                for e in visible_diffs(base, p, depths, verts, fixed,
                                                                       rm.mesh)],
                     "change_vs_previous_mm": [e * 1e3
                                               for e in visible_diffs(prev, p, depths, verts, fixed,
                                                                      rm.mesh)],
                     "diff_vs_finest_mm": [e * 1e3
                                           for e in visible_diffs(p, fine, depths, verts, fixed, rm.mesh)]})
        prev = p
    tube = conv["levels"][-2]["error_vs_finest_mm"]
    log.info("skin study at 50 mm: skin refinement moves the visible surface by "
             f"{[round(r['change_vs_unrefined_mm'][-1], 2) for r in rows]} mm, the tube refinement by "
             f"{tube[-1]:.2f} mm")
    return {"depths_m": depths.tolist(), "unrefined": unrefined.__dict__, "finest": st.levels[-1].__dict__,
            "unrefined_dofs": int(base["dofs"]), "unrefined_force_N_at_50mm": float(base["force"][-1]),
            "finest_force_N_at_50mm": float(fine["force"][-1]), "tube_change_mm": tube, "skins": rows}
