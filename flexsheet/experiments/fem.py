"""``flexsheet experiment fem --out DIR [--quick]``: accuracy against speed, Hertz check, stability curve.

Writes DIR/summary.json, DIR/accuracy_table.json (the table :mod:`nodes.fem.choose` reads), and PNG charts
with a JSON of the same numbers beside each: accuracy_speed.png/.json, hertz.png/.json, stability.png/.json.
The reference is P2 on the finest mesh that fits in time (``--quick``: a coarser P2 mesh and two depths).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from nodes.fem.choose import choose, evaluate_spec
from nodes.fem.contact import finger_at
from nodes.fem.material import Material
from nodes.fem.mesh import MeshSpec, cylinder_mesh
from nodes.fem.realtime import RealtimeModel
from nodes.fem.solver import FemModel, element_checks, solve_corotational, solve_full

__all__ = ["main"]

FINGER_R = 0.008
TARGET = 0.0007


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexsheet experiment fem", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example: flexsheet experiment fem --out docs/figures/fem --quick")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--quick", action="store_true", help="small reference and few meshes (< 60 s)")
    p.add_argument("--nu", type=float, default=Material().nu, help="Poisson's ratio (default %(default)s)")
    p.add_argument("--E", type=float, default=Material().E, help="Young's modulus, Pa (default %(default)s)")
    return p


def _timeit(fn, n: int) -> float:
    """Median wall time of ``n`` calls, s (median: the shared machine has load spikes)."""
    fn()
    ts = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        fn()
        ts[i] = time.perf_counter() - t
    return float(np.median(ts))


def main(argv: list[str] | None = None) -> int:
    """Run the experiment; returns 0. See the module docstring for the outputs."""
    args = _parser().parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    mat = Material(args.E, args.nu)
    t_start = time.perf_counter()
    if args.quick:
        ref_spec = MeshSpec(0.012, 0.003, 0.015)
        depths = [0.005, 0.03]
        cands = [(MeshSpec(0.010, 0.004, 0.012), 1), (MeshSpec(0.012, 0.006, 0.012), 2),
                 (MeshSpec(0.012, 0.004, 0.012), 2)]
        stab_depths = [0.01, 0.03]
        hertz_depths = [0.0005, 0.001, 0.002]
        check_spec = None
    else:
        ref_spec = MeshSpec(0.010, 0.002, 0.015)
        depths = [0.005, 0.01, 0.02, 0.03, 0.04, 0.05]
        cands = [(MeshSpec(h, hf, rr), 1) for h, hf, rr in ((0.012, 0.004, 0.012), (0.010, 0.003, 0.012),
                                                             (0.008, 0.003, 0.012), (0.008, 0.002, 0.015),
                                                             (0.006, 0.002, 0.015))]
        cands += [(MeshSpec(h, hf, rr), 2) for h, hf, rr in ((0.016, 0.006, 0.012), (0.012, 0.006, 0.012),
                                                             (0.012, 0.005, 0.012), (0.012, 0.004, 0.012),
                                                             (0.012, 0.003, 0.012), (0.010, 0.004, 0.012))]
        stab_depths = [0.0025, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05]
        hertz_depths = [0.0005, 0.00075, 0.001, 0.0015, 0.002]
        check_spec = MeshSpec(0.008, 0.0015, 0.015)

    hertz_spec = MeshSpec(0.012, 0.002, 0.008)     # P2, 2 mm under the finger: contact radius ≥ 2 mm at 0.5 mm
    depth_range = (0.005, 0.03)                     # the paper pushes to S = 30 mm (Fig. 12)

    # 1. reference
    t = time.perf_counter()
    ref_mesh = cylinder_mesh(ref_spec)
    ref_model = FemModel(ref_mesh, mat, order=2)
    refs = {d: solve_full(ref_model, finger_at(0.0, d, FINGER_R, ref_mesh.radius, ref_mesh.center)) for d in depths}
    ref_s = time.perf_counter() - t
    print(f"reference P2 {ref_spec.key()}: {ref_model.n_dofs} DOF, {len(depths)} depths in {ref_s:.1f} s", flush=True)
    ref_check = None
    if check_spec is not None:   # how converged is the reference itself? (finer P2, 30 mm)
        cm = cylinder_mesh(check_spec)
        cmod = FemModel(cm, mat, order=2)
        fine = {0.03: solve_full(cmod, finger_at(0.0, 0.03, FINGER_R, cm.radius, cm.center))}
        ev = evaluate_spec(ref_spec, cmod, fine, mat, FINGER_R, order=2)
        ref_check = {"finer_spec": check_spec.__dict__, "finer_dofs": cmod.n_dofs,
                     "surface_error_mm_at_30mm": ev["surface_error_m"]["0.0300"] * 1e3,
                     "surface_error_all_mm_at_30mm": ev["surface_error_all_m"]["0.0300"] * 1e3,
                     "force_error_pct_at_30mm": ev["force_error_pct"]["0.0300"]}
        print("reference vs finer P2:", ref_check, flush=True)

    # 2. candidates: accuracy and speed
    table = {"nu": mat.nu, "finger_radius": FINGER_R, "reference": {"spec": ref_spec.__dict__, "order": 2,
                                                                   "dofs": ref_model.n_dofs}, "candidates": []}
    rows = []
    d30 = min(depths, key=lambda d: abs(d - 0.03))
    for spec, order in cands:
        ev = evaluate_spec(spec, ref_model, refs, mat, FINGER_R, order=order)
        table["candidates"].append(ev)
        rm = RealtimeModel(spec, mat, FINGER_R, cache_dir=None, order=order)
        fg = finger_at(0.0, d30, FINGER_R, rm.mesh.radius, rm.mesh.center)
        upd = _timeit(lambda rm=rm, fg=fg: rm.update_finger(fg), 50 if args.quick else 300)
        sparse = _timeit(lambda rm=rm, fg=fg: solve_full(rm.model, fg), 1 if args.quick else 3)
        k = f"{d30:.4f}"
        rows.append({"spec": spec.__dict__, "order": order, "mesh_nodes": ev["mesh_nodes"], "dofs": ev["dofs"],
                     "precompute_s": rm.precompute_s, "update_ms": upd * 1e3, "sparse_ms": sparse * 1e3,
                     "surface_error_mm_at_30mm": ev["surface_error_m"][k] * 1e3,
                     "surface_error_all_mm_at_30mm": ev["surface_error_all_m"][k] * 1e3,
                     "surface_rms_mm_at_30mm": ev["surface_rms_m"][k] * 1e3,
                     "force_error_pct_at_30mm": ev["force_error_pct"][k],
                     "max_error_mm": max(ev["surface_error_m"].values()) * 1e3})
        print(f"  P{order} {spec.key()}: {ev['mesh_nodes']} nodes {ev['dofs']} DOF, err@30 "
              f"{rows[-1]['surface_error_mm_at_30mm']:.2f} mm (all {rows[-1]['surface_error_all_mm_at_30mm']:.2f}, "
              f"rms {rows[-1]['surface_rms_mm_at_30mm']:.2f}), force {rows[-1]['force_error_pct_at_30mm']:+.1f} %, "
              f"update {upd * 1e3:.3f} ms, sparse {sparse * 1e3:.0f} ms, precompute {rm.precompute_s:.2f} s",
              flush=True)
    # corotational timing and self-convergence at 30 mm on the candidate meshes (quick: two of them)
    corot = []
    p1_specs = [s for s, o in cands if o == 1]
    for spec in (p1_specs[:1] if args.quick else p1_specs):
        mesh = cylinder_mesh(spec)
        model = FemModel(mesh, mat)
        fg = finger_at(0.0, d30, FINGER_R, mesh.radius, mesh.center)
        t = time.perf_counter()
        sol, it, conv = solve_corotational(model, fg)
        corot.append({"spec": spec.__dict__, "mesh_nodes": len(mesh.points), "ms": (time.perf_counter() - t) * 1e3,
                      "iterations": it, "converged": conv, "force_N": sol.force, "model": model, "sol": sol})
    fine = corot[-1]
    for c in corot:
        surf = np.flatnonzero(c["model"].boundary & ~c["model"].fixed)
        u_ref = _p1_probe(fine["model"], fine["sol"].u, c["model"].points[surf])
        c["surface_error_mm_vs_finest"] = float(np.linalg.norm(c["sol"].u[surf] - u_ref, axis=1).max() * 1e3)
        c["force_error_pct_vs_finest"] = 100.0 * (c["force_N"] - fine["force_N"]) / fine["force_N"]
        del c["model"], c["sol"]
    table["depths"] = depths
    with open(os.path.join(args.out, "accuracy_table.json"), "w") as fh:
        json.dump(table, fh, indent=1)

    # 3. choice
    ch = choose(table, TARGET, depth_range[0], depth_range[1], mat.nu, FINGER_R)
    ch_full = choose(table, TARGET, min(depths), max(depths), mat.nu, FINGER_R)
    print("choice over the whole tabulated range:", ch_full.reason, flush=True)
    chosen = next(r for r in rows if r["spec"] == ch.spec.__dict__ and r["order"] == ch.order)
    print("choice:", ch.reason, flush=True)

    # 4. Hertz check (small depth, P2 on a mesh refined under the finger)
    hz_mesh = cylinder_mesh(hertz_spec)
    hz_model = FemModel(hz_mesh, mat, order=2)
    hz_F = [solve_full(hz_model, finger_at(0.0, d, FINGER_R, hz_mesh.radius, hz_mesh.center)).force for d in hertz_depths]
    if min(hz_F) <= 0:
        raise RuntimeError(f"Hertz check: no contact at some depth {hertz_depths}: forces {hz_F}")
    slope, _ = np.polyfit(np.log(hertz_depths), np.log(hz_F), 1)
    # sphere (R1) on a cylinder (R2 across, flat along the axis): principal relative radii R' = R1 R2/(R1+R2),
    # R'' = R1; equivalent radius sqrt(R' R'') (Johnson, Contact Mechanics, §4.2; ellipticity ignored)
    R_eff = math.sqrt(FINGER_R * (FINGER_R * hz_mesh.radius / (FINGER_R + hz_mesh.radius)))
    F_hertz = [4.0 / 3.0 * mat.E_star * math.sqrt(R_eff) * d ** 1.5 for d in hertz_depths]
    hertz = {"depths_m": hertz_depths, "force_N": hz_F, "hertz_force_N": F_hertz, "exponent": float(slope),
             "hertz_error_pct": float(abs(slope - 1.5) / 1.5 * 100.0),
             "finite_size_factor": float(np.mean(np.array(hz_F) / np.array(F_hertz))),
             "R_eff_m": R_eff, "E_star_Pa": mat.E_star, "mesh": hertz_spec.__dict__, "order": 2,
             "mesh_nodes": len(hz_mesh.points),
             "note": "bonded contact on a finite cylinder held on its back half; exponent is the check"}
    print(f"hertz: exponent {slope:.3f} ({hertz['hertz_error_pct']:.1f} % from 1.5), F/F_hertz "
          f"{hertz['finite_size_factor']:.2f}", flush=True)

    # 5. stability: linear vs corotational against depth on the chosen mesh
    mesh = cylinder_mesh(ch.spec)
    model = FemModel(mesh, mat)
    surf = np.flatnonzero(model.boundary & ~model.fixed)
    stab = {"depths_m": stab_depths, "linear_force_N": [], "corot_force_N": [], "linear_max_strain": [],
            "corot_max_strain": [], "linear_inverted": [], "corot_inverted": [], "lin_vs_corot_mm": [],
            "corot_converged": []}
    u0 = None
    for d in stab_depths:
        fg = finger_at(0.0, d, FINGER_R, mesh.radius, mesh.center)
        lin = solve_full(model, fg)
        co, _, conv = solve_corotational(model, fg, u0=u0)
        u0 = co.u
        s_l, i_l = element_checks(mesh.points, mesh.tets, lin.u)
        s_c, i_c = element_checks(mesh.points, mesh.tets, co.u)
        stab["linear_force_N"].append(lin.force)
        stab["corot_force_N"].append(co.force)
        stab["linear_max_strain"].append(s_l)
        stab["corot_max_strain"].append(s_c)
        stab["linear_inverted"].append(i_l)
        stab["corot_inverted"].append(i_c)
        stab["corot_converged"].append(bool(conv))
        stab["lin_vs_corot_mm"].append(float(np.linalg.norm(lin.u[surf] - co.u[surf], axis=1).max() * 1e3))
    print("stability:", {k: [round(v, 3) if isinstance(v, float) else v for v in vals] for k, vals in stab.items()},
          flush=True)

    summary = {
        "realtime": {"method": "condensed", "order": chosen["order"], "mesh_nodes": chosen["mesh_nodes"],
                     "dofs": chosen["dofs"], "mesh": chosen["spec"],
                     "surface_error_all_mm_at_30mm": chosen["surface_error_all_mm_at_30mm"],
                     "update_ms": chosen["update_ms"], "surface_error_mm_at_30mm": chosen["surface_error_mm_at_30mm"],
                     "force_error_pct_at_30mm": chosen["force_error_pct_at_30mm"],
                     "precompute_s": chosen["precompute_s"], "choice": ch.reason, "target_mm": TARGET * 1e3,
                     "depth_range_m": list(depth_range), "choice_over_5_50mm": ch_full.reason},
        "hertz_error_pct": hertz["hertz_error_pct"],
        "hertz": hertz,
        "reference": {"spec": ref_spec.__dict__, "order": 2, "dofs": ref_model.n_dofs, "seconds": ref_s,
                      "vs_finer": ref_check},
        "material": {"E": mat.E, "nu": mat.nu}, "finger_radius_m": FINGER_R, "quick": args.quick,
        "note": "timings on a shared 2-core machine (pessimistic)",
        "wall_s": time.perf_counter() - t_start,
    }
    _write(args.out, "accuracy_speed", {"candidates": rows, "corotational": corot, "depth_m": d30})
    _write(args.out, "hertz", hertz)
    _write(args.out, "stability", stab)
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    _plots(args.out, rows, corot, hertz, stab, chosen)
    print(json.dumps(summary["realtime"], indent=1))
    print(f"done in {summary['wall_s']:.1f} s -> {args.out}")
    return 0


def _p1_probe(model: FemModel, u_pts: np.ndarray, x: np.ndarray) -> np.ndarray:
    full = np.zeros(model.n_dofs)
    full[model.dofs] = u_pts
    return model.probe(x, full)


def _write(out: str, name: str, data: dict) -> None:
    with open(os.path.join(out, name + ".json"), "w") as fh:
        json.dump(data, fh, indent=1)


def _plots(out, rows, corot, hertz, stab, chosen) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    n = np.array([r["mesh_nodes"] for r in rows])
    err = np.array([r["surface_error_mm_at_30mm"] for r in rows])
    p2 = np.array([r["order"] == 2 for r in rows])
    up = np.array([r["update_ms"] for r in rows])
    sm = np.array([r["sparse_ms"] for r in rows])
    ax.scatter(up[~p2], err[~p2], c="C0", marker="o", label="condensed P1, per update")
    ax.scatter(up[p2], err[p2], c="C0", marker="D", label="condensed P2, per update")
    ax.scatter(sm[~p2], err[~p2], c="C1", marker="o", label="full sparse P1, per update")
    ax.scatter(sm[p2], err[p2], c="C1", marker="D", label="full sparse P2, per update")
    ax.scatter([c["ms"] for c in corot], [c["surface_error_mm_vs_finest"] for c in corot], c="C2", marker="^",
               label="corotational (vs finest corot.), per solve")
    for r, e in zip(rows, err, strict=True):
        ax.annotate(str(r["mesh_nodes"]), (r["update_ms"], e), fontsize=7)
    ax.axhline(TARGET * 1e3, color="k", ls="--", lw=0.8, label="target 0.7 mm (1 projector px)")
    ax.axvline(1.0, color="grey", ls=":", lw=0.8, label="1 kHz")
    ax.scatter([chosen["update_ms"]], [chosen["surface_error_mm_at_30mm"]], s=150, facecolors="none",
               edgecolors="r", label="chosen")
    ax.set_xscale("log")
    ax.set_xlabel("time per update (ms), shared 2-core CPU")
    ax.set_ylabel("max surface error outside finger, 30 mm push (mm)")
    ax.set_title(f"Accuracy vs speed (labels: mesh nodes; n = {n.min()}–{n.max()})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "accuracy_speed.png"), dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    d = np.array(hertz["depths_m"]) * 1e3
    ax.loglog(d, hertz["force_N"], "o-", label=f"FEM (exponent {hertz['exponent']:.3f})")
    ax.loglog(d, hertz["hertz_force_N"], "k--", label="Hertz half-space, F ∝ d^1.5")
    ax.set_xlabel("push depth (mm)")
    ax.set_ylabel("force (N)")
    ax.set_title(f"Hertz check: R_eff={hertz['R_eff_m'] * 1e3:.2f} mm, E*={hertz['E_star_Pa'] / 1e3:.1f} kPa, "
                 f"F/F_H={hertz['finite_size_factor']:.2f}", fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "hertz.png"), dpi=120)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    d = np.array(stab["depths_m"]) * 1e3
    a1.plot(d, stab["linear_force_N"], "o-", label="linear")
    a1.plot(d, stab["corot_force_N"], "^-", label="corotational")
    a1.set_xlabel("push depth (mm)")
    a1.set_ylabel("force (N)")
    a1.legend()
    a2.plot(d, stab["lin_vs_corot_mm"], "o-", label="max |u_lin − u_corot| (mm)")
    a2.plot(d, stab["linear_inverted"], "s-", label="inverted tets, linear")
    a2.plot(d, stab["corot_inverted"], "^-", label="inverted tets, corotational")
    a2.plot(d, np.array(stab["linear_max_strain"]) * 10, "x--", label="linear max strain ×10")
    a2.set_xlabel("push depth (mm)")
    a2.set_yscale("symlog")
    a2.legend(fontsize=7)
    fig.suptitle("Where linear breaks (chosen mesh)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stability.png"), dpi=120)
    plt.close(fig)
