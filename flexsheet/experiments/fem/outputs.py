"""What the full run writes besides the studies: the failure map (:func:`failure_map`), the node's model table
(:func:`model_table`, ``flexsheet/fem/model_table.json``), ``summary.json`` (:func:`summary`), and the JSON
writer of every output (:func:`write_json`)."""

from __future__ import annotations

import json
import os

import numpy as np

from flexsheet.fem.material import Material
from flexsheet.fem.reference.settings import FINGER_R, TARGET, Settings, law_name
from flexsheet.fem.reference.versions import solver_tag


def failure_map(cases: list[dict], cand: dict) -> dict:
    """Per candidate: error (mm) on the (azimuth, depth) grid of the validation cases and where it breaks."""
    angles = sorted({c["angle_deg"] for c in cases})
    depths = sorted({c["depth"] for c in cases})
    out = {"angles_deg": angles, "depths_mm": [d * 1e3 for d in depths], "target_mm": TARGET * 1e3,
           "models": {}}
    for k, v in cand.items():
        grid = np.full((len(angles), len(depths)), np.nan)
        for c, e in zip(cases, v["errors_m"], strict=True):
            grid[angles.index(c["angle_deg"]), depths.index(c["depth"])] = e * 1e3
        breaks = {}
        for i, a in enumerate(angles):
            bad = [depths[j] * 1e3 for j in range(len(depths)) if grid[i, j] > TARGET * 1e3]
            breaks[f"{a:g}"] = min(bad) if bad else None
        out["models"][k] = {"name": v["name"], "error_mm": grid.tolist(), "breaks_at_depth_mm": breaks}
    return out


def model_table(cases: list[dict], cand: dict, law: str = "neo-Hookean") -> dict:
    """``flexsheet/fem/model_table.json``: each candidate's worst visible error per depth (over azimuths) and
    speed."""
    depths = sorted({c["depth"] for c in cases})
    rows = []
    for v in cand.values():
        by = {f"{d:.4f}": max(e for c, e in zip(cases, v["errors_m"], strict=True) if c["depth"] == d)
              for d in depths}
        rows.append({"kind": v["kind"], "name": v["name"], "max_error_m_by_depth": by,
                     "update_ms": v["time_ms"]["median"]})
    return {"target_m": TARGET, "finger_radius": FINGER_R,
            "angles_deg": sorted({c["angle_deg"] for c in cases}),
            "note": f"worst visible-surface error against the {law} reference over the tabulated azimuths",
            "candidates": rows}


def summary(st: Settings, conv: dict, cand: dict, cases: list[dict], snap_info: dict, mat: Material,
            wall: float) -> dict:
    """The ``summary.json`` object (the scene's keys first)."""
    s = cand["snapshots"]
    lin = cand["linear"]
    worst = max(s["errors_m"])
    wc = cases[int(np.argmax(s["errors_m"]))]
    ho = [e for c, e in zip(cases, s["errors_m"], strict=True) if c.get("held_out")]
    at = [e for c, e in zip(cases, s["errors_m"], strict=True) if not c.get("held_out")]
    snap_info = snap_info | {
        "max_visible_error_mm_held_out_depths": max(ho) * 1e3 if ho else None,
        "max_visible_error_mm_snapshot_depths": max(at) * 1e3 if at else None,
        "validation": "azimuth 0 against the finest convergence mesh every "
                      f"{st.fine_step * 1e3:g} mm; the depths between snapshots are held out (interpolation "
                      "error); "
                      + ("at the snapshot depths only the surface-grid sampling is checked; the mesh's own "
                         "error is the reference's convergence figure" if st.snap_spec == st.levels[-1] else
                         "the snapshots come from a coarser mesh than the reference (h_fine "
                         f"{st.snap_spec.h_fine * 1e3:g} mm against {st.levels[-1].h_fine * 1e3:g} mm), so "
                         "every figure includes that mesh's own error")
                      + (f"; held-out azimuths {[f'{a:g}' for a in st.holdout_deg]} deg against their own "
                         f"solves on the snapshot mesh (interpolation between the snapshot azimuths "
                         f"{[f'{a:g}' for a in st.grid.angles_deg]} deg; the mesh's own error not included "
                         "there)"
                         if st.holdout_deg else ""),
        "max_visible_error_mm_by_azimuth": {
            f"{a:g}": max(e for c, e in zip(cases, s["errors_m"], strict=True) if c["angle_deg"] == a) * 1e3
            for a in sorted({c["angle_deg"] for c in cases})}}
    return {
        "realtime": {"method": "snapshots", "update_ms": s["time_ms"]["median"],
                     "update_ms_p90": s["time_ms"]["p90"],
                     "max_visible_error_mm_0_50": worst * 1e3,
                     "worst_case": {"angle_deg": wc["angle_deg"], "depth_mm": wc["depth"] * 1e3},
                     "angles_checked_deg": sorted({c["angle_deg"] for c in cases}), "target_mm": TARGET * 1e3,
                     "footprint": f"vertices whose deformed position (the reference's) lies within "
                                  f"{FINGER_R * 1e3 + 2:.0f} mm of the push axis are hidden by the finger "
                                  "and left out (the footprint under the tip and the wall dragged onto the "
                                  "finger's side)",
                     "max_visible_error_mm_0_50_rest_footprint": max(s["errors_rest_footprint_m"]) * 1e3,
                     **snap_info},
        "linear": {"update_ms": lin["time_ms"]["median"],
                   "max_visible_error_mm_0_50": max(lin["errors_m"]) * 1e3},
        "reference": _reference(st, conv, mat),
        "material": {"E": mat.E, "nu": mat.nu, "model": "gent" if mat.gent else "neo_hookean",
                     **({"Jm": mat.Jm} if mat.gent else {})},
        "finger_radius_m": FINGER_R, "quick": st.quick,
        "note": "timings on a shared 2-core machine (pessimistic)", "wall_s": wall,
    }


def _reference(st: Settings, conv: dict, mat: Material) -> dict:
    """The ``reference`` block of ``summary.json``: the convergence, penalty and skin studies, the levels."""
    pen, skin = conv["penalty_study"], conv["skin_study"]
    conv_keys = ("monotone_decrease", "last_refinement_change_mm", "finest_inverted_nodal_at_50mm",
                 "finest_inverted_qp_at_50mm", "finest_inverted_nodal_visible_max", "finest_inverted_qp_max",
                 "finest_newton_converged", "converged_to_depth_mm", "criterion", "mesh_converged")
    scales = [{k: r[k] for k in ("penalty_scale", "penetration_mm_at_50mm", "force_N_at_50mm", "cpu_seconds")}
              | {"error_vs_stiffest_mm_max": max(r["error_vs_stiffest_mm"])} for r in pen["scales"]]
    skins = [{k: r[k] for k in ("skin_h_m", "dofs", "cpu_seconds", "newton_converged", "force_N_at_50mm")}
             | {"change_vs_unrefined_mm_at_50mm": r["change_vs_unrefined_mm"][-1],
                "change_vs_previous_mm_at_50mm": r["change_vs_previous_mm"][-1],
                "diff_vs_finest_mm_at_50mm": r["diff_vs_finest_mm"][-1]} for r in skin["skins"]]
    levels = [{k: lv[k] for k in ("h_fine_m", "dofs", "seconds", "cpu_seconds", "newton_converged")}
              | {"error_vs_finest_mm_max": max(lv["error_vs_finest_mm"]),
                 "error_vs_finest_mm_at_50mm": lv["error_vs_finest_mm"][-1],
                 "force_N_at_50mm": lv["force_N"][-1],
                 "inverted_nodal_at_50mm": lv["inverted_nodal"][-1],
                 "inverted_qp_max": max(lv["inverted_qp"])}
              for lv in conv["levels"]]
    return {"converged": conv["converged"],
            "model": f"compressible {law_name(mat)}, total Lagrangian, P2, Newton + load stepping, rigid "
                     f"finger (penalty), {st.contact} contact",
            "contact": st.contact, "solver": solver_tag(st.contact), **{k: conv[k] for k in conv_keys},
            "penalty_study": {k: pen[k]
                              for k in ("default_scale", "default_vs_10x_stiffer_mm", "tolerance_mm",
                                        "converged")} | {"h_fine_m": pen["mesh"]["h_fine"],
                                                         "scales": scales},
            "skin_study": {"tube_change_mm_at_50mm": skin["tube_change_mm"][-1], "skins": skins},
            "levels": levels, "figures": "convergence.json, convergence.png"}


def write_json(out: str, name: str, data: dict) -> None:
    """Write ``data`` as ``out``/``name``.json (indented one space)."""
    with open(os.path.join(out, name + ".json"), "w") as fh:
        json.dump(data, fh, indent=1)
