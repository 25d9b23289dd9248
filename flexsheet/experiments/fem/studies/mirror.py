"""The mirror study (``--mirror-study``, ``mirror_study.json``, :func:`mirror_study`): the azimuth-0 push on
cut half models against the quarter models, each half model's own asymmetry (:func:`mirror_asymmetry`), and
the quarter models' stability against modes antisymmetric in z (:func:`mirror_stability`,
:func:`mirror_blocks`)."""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT, PENALTY_SCALE, capsule_at
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import (
    check_dofs,
    push_depths,
    reference_key,
    reference_model,
    reference_path,
)
from flexsheet.fem.reference.settings import FINGER_R, Settings
from flexsheet.fem.reference.snapshot_build import folded_probe, unfolded_sample
from flexsheet.fem.sparse_factor import NotPositiveDefinite, factor
from flexsheet.fem.visible_error import visible_diffs, visible_vertices

log = logging.getLogger(__name__)


def mirror_asymmetry(path: dict, spec: RefSpec, depths: np.ndarray, mat: Material,
                     rm: RealtimeModel) -> list[float]:
    """Per depth (D,) m, the largest |u(x) − M·u(M·x)| (m) over the rendered vertices x visible on the
    deformed surface of an azimuth-0 :func:`reference_path` ``path`` solved on ``spec``'s mesh, M the mirror
    in z through the cylinder's axis: how far the solution is from mirror-symmetric. u(M·x) is probed from the
    path's DOF field (``u_dof``) on the re-meshed model (gmsh is deterministic). A quarter model (``half_z``)
    gives 0 up to float32 rounding, by construction."""
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    mirrored = verts.copy()
    mirrored[:, 2] = 2 * rm.mesh.center[2] - mirrored[:, 2]
    model = reference_model(spec, 0.0, mat)
    check_dofs(path, model)
    P = folded_probe(model, mirrored)
    out = []
    for j, d in enumerate(depths):
        um = unfolded_sample(P, path["u_dof"][j].astype(float), mirrored, model)
        um[:, 2] *= -1.0
        vis = visible_vertices(verts + path["u"][j], fixed, 0.0, d, rm.mesh)
        out.append(float(np.linalg.norm(path["u"][j] - um, axis=1)[vis].max()))
    return out


def mirror_blocks(m: HyperelasticModel) -> tuple[np.ndarray, np.ndarray]:
    """The fixed DOFs (P, 3) bool of the two symmetry blocks of a quarter model ``m`` (``sym_z``): symmetric —
    ``m``'s own BCs (support, y plane u_y = 0, z plane u_z = 0); antisymmetric in z — on the z plane u_x = u_y
    = 0 and u_z free (the y plane keeps u_y = 0 and the support stays fixed, so both are symmetric in y).
    Raises ``ValueError`` when ``m`` has no z mirror plane."""
    if not m.sym_z:
        raise ValueError("mirror_blocks needs a quarter model (sym_z)")
    P = len(m.points)
    sym = m.fixed_mask.reshape(P, 3).copy()
    anti = sym.copy()
    anti[np.abs(m.points[:, 2] - m.mesh.center[2]) < 1e-9] = [True, True, False]
    anti[m.support] = True
    return sym, anti


def mirror_stability(path: dict, spec: RefSpec, depths: np.ndarray, mat: Material,
                     contact: str = DEFAULT_CONTACT,
                     n_eig: int = 2) -> dict:
    """Is the mirror-symmetric azimuth-0 solution of a quarter model (``spec.half_z``; its
    :func:`reference_path` ``path`` at ``depths`` (D,) m) stable against modes antisymmetric in z, which the
    quarter model cannot make? At a symmetric equilibrium on a symmetric mesh the tangent splits into a
    symmetric and an antisymmetric block (:func:`mirror_blocks`; both symmetric in y). Per converged state:
    the lowest eigenvalue of each (N/m, unit-norm DOF vectors, so mesh-dependent; scipy ``eigsh``
    shift-invert, fixed start vector) and, definitively, whether the antisymmetric block is positive definite
    (CHOLMOD's Cholesky succeeds: :func:`flexsheet.fem.sparse_factor.factor`). An antisymmetric block that is
    not positive definite is a symmetry-breaking bifurcation; a small positive eigenvalue, a state a small
    asymmetry moves far (imperfection sensitivity, Koiter). Linear stability at the sampled states only: it
    does not exclude an asymmetric branch coexisting with the symmetric one. Returns {"sym_N_per_m",
    "anti_N_per_m", "anti_positive_definite", "residual_N" (D,) free residual norm (u_dof is float32), "dofs",
    "cpu_seconds"}. Raises ``ValueError`` for a spec without the z mirror plane or a contact law other than
    frictionless (the sticking anchors are not stored with the path), ``RuntimeError`` when the re-meshed
    model has another DOF count than the path (gmsh meshes differently)."""
    import scipy.sparse.linalg as sla

    if not spec.half_z:
        raise ValueError(f"mirror_stability needs a quarter model (half_z), got {spec.key()}")
    if contact != "frictionless":
        raise ValueError(f"mirror_stability supports the frictionless contact law only, got {contact!r}")
    tc = time.process_time()
    m = reference_model(spec, 0.0, mat)
    check_dofs(path, m)
    sym, anti = mirror_blocks(m)
    k = m.penalty()
    out = {"sym_N_per_m": [], "anti_N_per_m": [], "anti_positive_definite": [], "residual_N": [],
           "dofs": int(m.n)}
    for j, d in enumerate(depths):
        u = path["u_dof"][j].astype(float)
        r, K = m.residual_tangent(u, capsule_at(0.0, float(d), FINGER_R, m.mesh.radius, m.mesh.center), k)
        out["residual_N"].append(float(np.linalg.norm(r[~sym.ravel()])))
        for name, fixed in (("sym_N_per_m", sym), ("anti_N_per_m", anti)):
            fr = np.flatnonzero(~fixed.ravel())
            Kf = K[fr][:, fr].tocsc()
            ev = sla.eigsh(Kf, k=n_eig, sigma=-1e-3 * float(np.abs(Kf.diagonal()).mean()), which="LM",
                           v0=np.ones(len(fr)), return_eigenvectors=False)
            out[name].append(float(np.min(ev)))
            if name == "anti_N_per_m":
                try:
                    factor(Kf, "cholmod")
                    out["anti_positive_definite"].append(True)
                except NotPositiveDefinite:
                    out["anti_positive_definite"].append(False)
    out["cpu_seconds"] = time.process_time() - tc
    return out


def mirror_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict,
                 fine: dict) -> dict:
    """Does the z mirror plane change the azimuth-0 answer? The convergence meshes are quarter models (u_z = 0
    on the plane z = z_O through the push axis, so their solution is mirror-symmetric by construction); every
    other azimuth, the held-out check and the node table's off-axis snapshots are half models, *cut*: meshed
    with nodes on the plane through their push axis but no BC there (:class:`RefSpec` ``cut``,
    :data:`flexsheet.fem.snapshots.DEFAULT_REF_SPEC`; uncut half models were 8–12 % stiffer at 40–50 mm than
    the quarter models of the same h_fine, docs/fem.md). Here the azimuth-0 push is solved on cut half models
    (``st.half_levels``, h_fine m, else as the convergence levels) and compared, every ``st.fine_step``, with
    the finest quarter model (``fine``) and with the quarter model of the same h_fine (from ``conv``'s levels,
    when there is one): per level the force (N), the largest visible-surface difference (mm) and the
    solution's own asymmetry, the largest |u(x) − M·u(M·x)| (mm) over the rendered vertices visible on it, M
    the mirror in z (u at M·x probed from the half model's field). A half-model solution asymmetric well
    beyond the mesh's own asymmetry would have left the symmetric branch (a bifurcation); one close to the
    quarter model of the same h_fine says the off-axis snapshots' meshes are as good as the quarter models the
    convergence study measures. Also ``stability``: :func:`mirror_stability` of the last two quarter levels
    (frictionless contact only; cached)."""
    depths = push_depths(st.fine_step)
    verts = rm.rest_vertices.astype(float)
    fixed = rm.mesh.fixed[rm.surface_nodes]
    quarter = {round(lv["h_fine_m"], 9): lv for lv in conv["levels"]}
    rows = []
    for hf in st.half_levels:
        spec = replace(st.levels[-1], h_fine=hf, half_z=False, cut=True)
        p = reference_path(spec, 0.0, depths, mat, cache, verts, st.contact)
        asym = [a * 1e3 for a in mirror_asymmetry(p, spec, depths, mat, rm)]
        q = quarter.get(round(hf, 9))
        rows.append({"h_fine_m": hf, "spec": spec.__dict__, "dofs": int(p["dofs"]),
                     "cpu_seconds": float(p["cpu_seconds"]),
                     "newton_converged": bool(p["converged"].all()),
                     "newton_iterations": p["newton"].tolist(),
                     "force_N": p["force"].tolist(), "asymmetry_mm": asym,
                     "diff_vs_finest_quarter_mm": [e * 1e3
                                                   for e in visible_diffs(p, fine, depths, verts, fixed,
                                                                          rm.mesh)],
                     "quarter_same_h_dofs": int(q["dofs"]) if q else None,
                     "quarter_same_h_force_N": q["force_N"] if q and len(q["force_N"]) == len(depths)
                     else None})
        log.info(f"mirror study: half model (cut) h_fine {hf * 1e3:g} mm ({rows[-1]['dofs']} DOF) at 50 mm: "
                 f"{p['force'][-1]:.2f} N, {rows[-1]['diff_vs_finest_quarter_mm'][-1]:.2f} mm from the "
                 f"finest quarter model, asymmetry {asym[-1]:.2f} mm")
    stab = []
    # the next-to-finest (full mode: the node's) mesh and the
    # finest; sticking contact: its anchors are not stored
    for spec in (st.levels[-2:] if st.contact == "frictionless" else []):
        sd = depths if spec == st.levels[-1] else push_depths(st.depth_step)
        p = fine if spec == st.levels[-1] else reference_path(spec, 0.0, sd, mat, cache, verts, st.contact)
        t = time.perf_counter()
        key = cache_key("mirror_stability-2",
                        reference_key(spec, 0.0, sd, mat, verts, st.contact, PENALTY_SCALE))
        z, _, _ = cache.get_or_compute("stability", key,
                                       lambda spec=spec, p=p, sd=sd: {k: np.asarray(v) for k, v in
                                                                      mirror_stability(p, spec, sd, mat,
                                                                                       st.contact).items()},
                                       f"mirror stability of {spec.key()}")
        row = {"h_fine_m": spec.h_fine, "dofs": int(z["dofs"]), "depths_m": sd.tolist(),
               "sym_N_per_m": z["sym_N_per_m"].tolist(), "anti_N_per_m": z["anti_N_per_m"].tolist(),
               "anti_over_sym": (z["anti_N_per_m"] / z["sym_N_per_m"]).tolist(),
               "anti_positive_definite": z["anti_positive_definite"].tolist(),
               "residual_N": z["residual_N"].tolist(),
               "cpu_seconds": float(z["cpu_seconds"])}
        row["stable"] = bool(np.all(z["anti_positive_definite"]))
        stab.append(row)
        i = int(np.argmin(row["anti_over_sym"]))
        n_bad = len(sd) - int(np.sum(z["anti_positive_definite"]))
        verdict = "stable at every depth" if row["stable"] else f"UNSTABLE at {n_bad} of {len(sd)} depths"
        log.info(f"mirror stability, quarter model h_fine {spec.h_fine * 1e3:g} mm: antisymmetric modes "
                 f"{verdict}; lowest antisymmetric / symmetric eigenvalue {row['anti_over_sym'][i]:.3f} at "
                 f"{sd[i] * 1e3:g} mm ({time.perf_counter() - t:.0f} s)")
    return {"depths_m": depths.tolist(), "finest_quarter": st.levels[-1].__dict__,
            "finest_quarter_force_N": fine["force"].tolist(), "quarter_depths_m": conv["depths_m"],
            "quarter_levels": [{k: lv[k] for k in ("h_fine_m", "dofs", "force_N", "cpu_seconds")}
                               for lv in conv["levels"]],
            "half_levels": rows, "stability": stab}
