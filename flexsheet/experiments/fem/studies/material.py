"""The material study (``--material-study``, ``material_study.json``, :func:`material_study`): the reference's
convergence and an azimuth-0 snapshot table for the neo-Hookean and a Gent solid."""

from __future__ import annotations

import logging
import math

import numpy as np

from flexsheet.experiments.fem.candidates import azimuth0_table_errors
from flexsheet.experiments.fem.studies.convergence import convergence
from flexsheet.experiments.fem.studies.tip import tip_specs
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.paths import at_depths, push_depths, reference_path
from flexsheet.fem.reference.settings import TARGET, Settings
from flexsheet.fem.visible_error import visible_diffs

log = logging.getLogger(__name__)


def material_study(st: Settings, mats: tuple[Material, ...], cache: ArrayCache, rm: RealtimeModel) -> dict:
    """Does the reference converge with a strain-stiffening material? For each of ``mats`` (neo-Hookean and a
    Gent solid, :class:`flexsheet.fem.material.Material` ``Jm``; same E, ν, finger, penalty, meshes): the
    azimuth-0 mesh convergence of :func:`convergence` (its verdict, every level's visible-surface difference
    to the finest, force, largest Green–Lagrange strain), and an azimuth-0 snapshot table (``st.grid``'s
    depths) taken from the stable branch of the next-to-finest level (full mode: the node's 3.4 mm mesh)
    judged at every ``st.fine_step`` against that material's finest level — never against the solve it was
    sampled from; and the visible-surface distance between the materials' finest solutions (how far the choice
    of material moves what the display shows). Full mode also a tip check per material (the fold study's,
    :func:`tip_specs`: the next-to-finest level's tube with the push point alone refined further), its
    visible-surface distance to that level and to the finest (neo-Hookean: the apex the fold study found
    unresolved). Returns {"depths_mm", "target_mm", "materials": [{"name", "Jm", "convergence",
    "snapshots_azimuth0", "tip_check" (full mode)}], "difference_between_materials_mm", "what"}; lengths in
    mm."""
    depths = push_depths(st.depth_step)
    fdepths = push_depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    snap_d = st.grid.depths()
    chk = tip_specs(st)[1]
    rows, fines = [], []
    for mat in mats:
        conv, fine = convergence(st, mat, cache, rm)
        fines.append(at_depths(fine, fdepths, depths))
        cases = [{"angle_deg": 0.0, "depth": float(d), "u": fine["u"][j],
                  "held_out": bool(np.min(np.abs(snap_d - d)) > 1e-9)} for j, d in enumerate(fdepths)]
        src, err = azimuth0_table_errors(st, mat, cache, rm, st.levels[-2], cases)
        name = f"Gent, Jm {mat.Jm:g}" if mat.gent else "neo-Hookean"
        tip = {}
        if chk is not None:             # does refining the apex alone still move the visible surface?
            tp = reference_path(chk, 0.0, depths, mat, cache, verts, st.contact)
            plain = reference_path(st.levels[-2], 0.0, depths, mat, cache, verts, st.contact)
            tip = {"tip_check": {
                "spec": chk.__dict__, "dofs": int(tp["dofs"]),
                "newton_converged": bool(tp["converged"].all()),
                "difference_to_plain_level_mm": [e * 1e3
                                                 for e in visible_diffs(tp, plain, depths, verts, fixed,
                                                                        rm.mesh)],
                "difference_to_finest_mm": [e * 1e3
                                            for e in visible_diffs(tp, fines[-1], depths, verts, fixed,
                                                                   rm.mesh)],
                "max_strain": tp["max_strain"].tolist(), "force_N": tp["force"].tolist(),
                "cpu_seconds": float(tp["cpu_seconds"])}}
        rows.append({"name": name, "Jm": mat.Jm if mat.gent else None, "convergence": conv, **tip,
                     "snapshots_azimuth0": {
                         "mesh": st.levels[-2].__dict__, "dofs": int(src["dofs"]),
                         "error_mm": [e * 1e3 for e in err], "depths_mm": (fdepths * 1e3).tolist(),
                         "max_visible_error_mm": max(err) * 1e3,
                         "max_visible_error_mm_held_out_depths": max(
                             (e for c, e in zip(cases, err, strict=True) if c["held_out"]), default=math.nan)
                         * 1e3}})
        log.info(f"material study, {name}: converged {conv['converged']}, last refinement "
                 f"{conv['last_refinement_change_mm']:.3f} mm, azimuth-0 snapshots worst {max(err) * 1e3:.2f}"
                 " mm")
    diff = [e * 1e3 for e in visible_diffs(fines[0], fines[-1], depths, verts, fixed, rm.mesh)] \
        if len(fines) > 1 else []
    return {"depths_mm": (depths * 1e3).tolist(), "target_mm": TARGET * 1e3, "materials": rows,
            "difference_between_materials_mm": diff,
            "what": "azimuth-0 mesh convergence of the reference (convergence()) for each material, an "
                    "azimuth-0 snapshot table on the next-to-finest level judged against that material's "
                    "finest level, and the visible-surface distance between the first and the last "
                    "material's finest solutions (visible on the last's surface)"}
