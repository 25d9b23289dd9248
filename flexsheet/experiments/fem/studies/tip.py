"""The fold study's tip-refined sequence (:func:`tip_sequence`): the push tube and the material at the push
point refined together (:func:`tip_specs`), its convergence verdict (:func:`tip_verdict`) and azimuth-0
snapshot tables on its meshes (:func:`_tip_snapshots`)."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from flexsheet.experiments.fem.candidates import azimuth0_table_errors
from flexsheet.experiments.fem.studies.convergence import sequence_verdict
from flexsheet.experiments.fem.studies.fold_check import fold_path
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import push_depths, reference_path
from flexsheet.fem.reference.settings import TARGET, TIP_RADIUS, Settings
from flexsheet.fem.visible_error import visible_diffs

log = logging.getLogger(__name__)


def tip_specs(st: Settings) -> tuple[list[RefSpec], RefSpec | None]:
    """(the tip-refined sequence, coarse → fine: ``st.tip_levels`` (h_fine, tip_h) m on the finest level's
    spec with ``tip_radius`` :data:`TIP_RADIUS`; the tip check: the middle level with the finer tip
    ``st.tip_check``, or None when it is 0)."""
    seq = [replace(st.levels[-1], h_fine=hf, tip_h=th, tip_radius=TIP_RADIUS) for hf, th in st.tip_levels]
    chk = replace(seq[len(seq) // 2], tip_h=st.tip_check) if st.tip_check > 0 and len(seq) > 1 else None
    return seq, chk


def tip_verdict(e: np.ndarray, depths: np.ndarray, newton_ok: bool, inverted_qp: int,
                tip_change_mm: float | None) -> dict:
    """The tip sequence's verdict: ``e`` (L-1, D) mm each coarser level's visible difference to the finest at
    ``depths`` (D,) m (:func:`sequence_verdict`), the finest level's Newton convergence and inverted count,
    and ``tip_change_mm`` the tip check's largest change (mm; None without one). "converged": ≥ 3 levels,
    monotone, the last change and the tip check's each ≤ half the target, Newton converged, nothing
    inverted."""
    half = TARGET * 1e3 / 2
    monotone, last, to_depth = sequence_verdict(e, depths) if len(e) else (False, float("nan"), 0.0)
    conv = len(e) + 1 >= 3 and monotone and last <= half and bool(newton_ok) and int(inverted_qp) == 0
    crit = ("convergence.json's: at least 3 meshes, the visible-surface difference to the finest falls with "
            "every refinement (depths >= 5 mm), the last refinement changes it by <= half the 0.7 mm target, "
            "Newton converged at every load step of the finest mesh, no element of it inverted at a "
            "quadrature point")
    if tip_change_mm is not None:
        conv = conv and tip_change_mm <= half
        crit += "; and a finer tip alone on the middle level changes it by <= half the target (tip_check)"
    return {"monotone_decrease": monotone, "last_refinement_change_mm": last,
            "converged_to_depth_mm": to_depth,
            "converged": conv, "criterion": crit}


def tip_sequence(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, tube_fine: dict) -> dict:
    """The push at azimuth 0 on meshes that refine the push tube *and* the material at the push point (within
    :data:`TIP_RADIUS`; the material stretched over the fingertip, where the plain levels are unresolved)
    together (``st.tip_levels``). Per level: DOF, CPU, force, the largest strain and stretch, the
    visible-surface difference to the finest tip level and to the finest plain level (``tube_fine``); the
    sequence's verdict by :func:`convergence`'s criterion ("converged": ≥ 3 levels, monotone at every depth ≥
    5 mm, last change ≤ half the target, Newton converged at every step of the finest, nothing inverted at a
    quadrature point, and, with a tip check, that check within half the target too); the tip check: the middle
    level with a finer tip alone, its difference to that level (does the apex still move the visible
    surface?); the azimuth-0 snapshot tables of :func:`_tip_snapshots`."""
    depths = push_depths(st.depth_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    seq, chk = tip_specs(st)
    paths = [reference_path(s, 0.0, depths, mat, cache, verts, st.contact) for s in seq]
    rows = []
    for s, p in zip(seq, paths, strict=True):
        f = fold_path(s, 0.0, p, depths, mat, cache)
        rows.append({"h_fine_mm": s.h_fine * 1e3, "tip_h_mm": s.tip_h * 1e3,
                     "tip_radius_mm": s.tip_radius * 1e3,
                     "dofs": int(p["dofs"]), "cpu_seconds": float(p["cpu_seconds"]),
                     "force_N": p["force"].tolist(),
                     "newton_converged": bool(p["converged"].all()),
                     "inverted_qp_max": int(p["inverted_qp"].max()),
                     "newton_iterations": p["newton"].tolist(),
                     "max_principal_strain": p["max_strain"].tolist(),
                     "max_surface_stretch_ratio": f["all_max_stretch_ratio"].tolist(),
                     "max_winding_with_footprint": f["all_max_winding"].tolist(),
                     "n_penetrating": f["all_n_penetrating"].astype(int).tolist(),
                     "difference_to_finest_mm": [e * 1e3
                                                 for e in visible_diffs(p, paths[-1], depths, verts, fixed,
                                                                        rm.mesh)],
                     "difference_to_finest_plain_level_mm": [e * 1e3 for e in visible_diffs(
                         p, tube_fine, depths, verts, fixed, rm.mesh)]})
    out = {"levels": rows}
    tc = None
    if chk is not None:
        pc = reference_path(chk, 0.0, depths, mat, cache, verts, st.contact)
        mid = paths[len(seq) // 2]
        out["tip_check"] = {"h_fine_mm": chk.h_fine * 1e3, "tip_h_mm": chk.tip_h * 1e3,
                            "dofs": int(pc["dofs"]),
                            "cpu_seconds": float(pc["cpu_seconds"]),
                            "max_principal_strain": pc["max_strain"].tolist(),
                            "newton_iterations": pc["newton"].tolist(),
                            "difference_to_its_level_mm": [e * 1e3
                                                           for e in visible_diffs(pc, mid, depths, verts,
                                                                                  fixed, rm.mesh)],
                            "difference_to_finest_mm": [e * 1e3
                                                        for e in visible_diffs(pc, paths[-1], depths, verts,
                                                                               fixed, rm.mesh)]}
        tc = max(out["tip_check"]["difference_to_its_level_mm"])
    fine = rows[-1]
    out.update(tip_verdict(np.array([r["difference_to_finest_mm"] for r in rows[:-1]]), depths,
                           fine["newton_converged"], fine["inverted_qp_max"], tc))
    monotone, last = out["monotone_decrease"], out["last_refinement_change_mm"]
    out["snapshots"] = _tip_snapshots(st, mat, cache, rm, seq, paths[-1])
    log.info(f"tip sequence: last refinement {last:.3f} mm, monotone {monotone}, converged "
             f"{out['converged']}")
    return out


def _tip_snapshots(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, seq: list[RefSpec],
                   finest: dict) -> dict:
    """Azimuth-0 snapshot tables (``st.grid``'s depth step, from the stable branch as every table) on the
    next-to-finest tip level and on the next-to-finest plain level (full mode: the node's mesh), each judged
    against the finest tip level ``finest`` at every output depth (the depths between snapshots held out): the
    worst visible error (mm) and the depth from which it exceeds the target. ``rm``'s table is left as it
    was."""
    depths = push_depths(st.depth_step)
    snap_d = st.grid.depths()
    cases = [{"angle_deg": 0.0, "depth": float(d), "u": finest["u"][j],
              "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(depths)]
    rows = []
    for spec in (st.levels[-2], seq[-2]):
        src, err = azimuth0_table_errors(st, mat, cache, rm, spec, cases)
        err = np.array(err) * 1e3
        over = np.flatnonzero(err > TARGET * 1e3)
        rows.append({"spec": spec.key(), "h_fine_mm": spec.h_fine * 1e3, "tip_h_mm": spec.tip_h * 1e3,
                     "dofs": int(src["dofs"]), "error_mm": err.tolist(),
                     "max_visible_error_mm": float(err.max()),
                     "over_target_from_mm": float(depths[over[0]] * 1e3) if len(over) else None})
        log.info(f"tip snapshots {spec.key()}: azimuth 0 worst {err.max():.2f} mm against the finest tip "
                 "level")
    return {"azimuth_deg": 0.0, "snapshot_depth_step_mm": st.grid.depth_step * 1e3, "target_mm": TARGET * 1e3,
            "against": "the finest tip level, every output depth", "tables": rows}
