"""The linear mesh study (``--linear-study``, :func:`linear_study`): linear P1/P2 meshes against a fine linear
P2 solution (``accuracy_table.json``), the Hertz exponent check (:func:`_hertz`) and where linear elasticity
leaves the corotational solution (:func:`_stability`)."""

from __future__ import annotations

import logging
import math

import numpy as np

from flexsheet.experiments.fem.candidates import update_ms
from flexsheet.experiments.fem.outputs import write_json
from flexsheet.experiments.fem.plots import plot_linear_study
from flexsheet.fem.choose import choose, evaluate_spec
from flexsheet.fem.contact import finger_at
from flexsheet.fem.corotational import solve_corotational
from flexsheet.fem.deformation_checks import element_checks
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, cylinder_tet_mesh
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.settings import FINGER_R, TARGET
from flexsheet.fem.solver import FemModel, solve_full

log = logging.getLogger(__name__)


def linear_study(out: str, mat: Material) -> None:
    """Linear P1/P2 meshes against a fine linear P2 solution (``accuracy_table.json``, read by
    :func:`flexsheet.fem.choose.choose`), the Hertz exponent check and the linear/corotational stability
    curve. Writes linear_accuracy_speed, hertz, stability (.json/.png) and accuracy_table.json into
    ``out``."""
    ref_spec = MeshSpec(0.010, 0.002, 0.015)
    depths = [0.005, 0.01, 0.02, 0.03, 0.04, 0.05]
    cands = [(MeshSpec(h, hf, rr), 1) for h, hf, rr in ((0.012, 0.004, 0.012), (0.010, 0.003, 0.012),
                                                         (0.008, 0.003, 0.012), (0.008, 0.002, 0.015))]
    cands += [(MeshSpec(h, hf, rr), 2) for h, hf, rr in ((0.016, 0.006, 0.012), (0.012, 0.006, 0.012),
                                                         (0.012, 0.004, 0.012), (0.012, 0.003, 0.012),
                                                         (0.010, 0.004, 0.012))]
    ref_mesh = cylinder_tet_mesh(ref_spec)
    ref_model = FemModel(ref_mesh, mat, order=2)
    refs = {d: solve_full(ref_model, finger_at(0.0, d, FINGER_R, ref_mesh.radius, ref_mesh.center))
            for d in depths}
    table, rows = _linear_candidates(cands, ref_spec, ref_model, refs, mat)
    table["depths"] = depths
    write_json(out, "accuracy_table", table)
    ch = choose(table, TARGET, 0.005, 0.03, mat.nu, FINGER_R)
    log.info("linear mesh choice over 5-30 mm: " + ch.reason)
    write_json(out, "linear_accuracy_speed", {"candidates": rows, "depth_m": 0.03, "choice": ch.reason})
    hz = _hertz(mat)
    write_json(out, "hertz", hz)
    stab = _stability(ch.spec, mat)
    write_json(out, "stability", stab)
    plot_linear_study(out, rows, hz, stab)


def _linear_candidates(cands, ref_spec, ref_model, refs, mat):
    table = {"nu": mat.nu, "finger_radius": FINGER_R, "reference": {"spec": ref_spec.__dict__, "order": 2,
                                                                   "dofs": ref_model.n_dofs},
             "candidates": []}
    rows = []
    for spec, order in cands:
        ev = evaluate_spec(spec, ref_model, refs, mat, FINGER_R, order=order)
        table["candidates"].append(ev)
        rm = RealtimeModel(spec, mat, FINGER_R, cache_dir=None, order=order)
        fg = finger_at(0.0, 0.03, FINGER_R, rm.mesh.radius, rm.mesh.center)
        t = update_ms(rm, [0.0], [0.03], 100)["median"]
        rows.append({"spec": spec.__dict__, "order": order, "mesh_nodes": ev["mesh_nodes"],
                     "dofs": ev["dofs"],
                     "precompute_s": rm.precompute_s, "update_ms": t,
                     "surface_error_mm_at_30mm": ev["surface_error_m"]["0.0300"] * 1e3,
                     "force_error_pct_at_30mm": ev["force_error_pct"]["0.0300"],
                     "max_error_mm": max(ev["surface_error_m"].values()) * 1e3})
        log.info(f"  linear P{order} {spec.key()}: err@30 {rows[-1]['surface_error_mm_at_30mm']:.2f} mm, "
                 f"update {t:.3f} ms ({fg.depth * 1e3:.0f} mm)")
    return table, rows


def _hertz(mat: Material) -> dict:
    """Small-depth force exponent of the linear P2 model against Hertz (Johnson, Contact Mechanics §4.2)."""
    spec = MeshSpec(0.012, 0.002, 0.008)
    depths = [0.0005, 0.00075, 0.001, 0.0015, 0.002]
    mesh = cylinder_tet_mesh(spec)
    model = FemModel(mesh, mat, order=2)
    F = [solve_full(model, finger_at(0.0, d, FINGER_R, mesh.radius, mesh.center)).force for d in depths]
    if min(F) <= 0:
        raise RuntimeError(f"Hertz check: no contact at some depth {depths}: forces {F}")
    slope, _ = np.polyfit(np.log(depths), np.log(F), 1)
    R_eff = math.sqrt(FINGER_R * (FINGER_R * mesh.radius / (FINGER_R + mesh.radius)))
    FH = [4.0 / 3.0 * mat.E_star * math.sqrt(R_eff) * d ** 1.5 for d in depths]
    return {"depths_m": depths, "force_N": F, "hertz_force_N": FH, "exponent": float(slope),
            "hertz_error_pct": float(abs(slope - 1.5) / 1.5 * 100.0),
            "finite_size_factor": float(np.mean(np.array(F) / np.array(FH))), "R_eff_m": R_eff,
            "E_star_Pa": mat.E_star, "mesh": spec.__dict__, "order": 2, "mesh_nodes": len(mesh.points),
            "note": "bonded contact on a finite cylinder held on its back half; exponent is the check"}


def _stability(spec: MeshSpec, mat: Material) -> dict:
    """Linear against corotational (P1) over depth on ``spec``: strain, inverted tets, force, difference."""
    mesh = cylinder_tet_mesh(spec)
    model = FemModel(mesh, mat)
    surf = np.flatnonzero(model.boundary & ~model.fixed)
    depths = [0.0025, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05]
    keys = ("linear_force_N", "corot_force_N", "linear_max_strain", "corot_max_strain", "linear_inverted",
            "corot_inverted", "lin_vs_corot_mm", "corot_converged")
    stab = {"depths_m": depths, **{k: [] for k in keys}}
    u0 = None
    for d in depths:
        fg = finger_at(0.0, d, FINGER_R, mesh.radius, mesh.center)
        lin = solve_full(model, fg)
        co, _, conv = solve_corotational(model, fg, u0=u0)
        u0 = co.u
        s_l, i_l = element_checks(mesh.points, mesh.tets, lin.u)
        s_c, i_c = element_checks(mesh.points, mesh.tets, co.u)
        vals = (lin.force, co.force, s_l, s_c, i_l, i_c,
                float(np.linalg.norm(lin.u[surf] - co.u[surf], axis=1).max() * 1e3), bool(conv))
        for k, v in zip(keys, vals, strict=True):
            stab[k].append(v)
    return stab
