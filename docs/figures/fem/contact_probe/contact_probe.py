"""One-off (session 23; run from the repository root: python3 docs/figures/fem/contact_probe/contact_probe.py
[H_FINE_MM] [A0 A1 AMID]): does the cylinder table's azimuth miss come from the frictionless finger?

The node's table (frictionless finger, 3.4 mm mesh) is 2.77 mm off at the held-out 8.75 deg between its 7.5 and
10 deg pushes (docs/figures/fem/node_table). Here, on a coarser mesh of the same layout (default h_fine 4.5 mm,
the convergence study's level 2, cut half models), the same three pushes (A0, A1 and the held-out AMID, deg) are
solved with each contact law (frictionless: the stable branch, as the table; sticking: the loading path, a
sticking contact has no other), a two-azimuth table [A0, A1] is built per law and judged at AMID against that
law's own solve, as node_table_holdout judges (largest visible-surface distance, mm). Beside it: how far the two
laws' surfaces lie apart at each azimuth (the contact law's own effect on what is displayed). Writes
contact_probe.json in the working folder. Two solver processes."""
import json
import multiprocessing
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, ".")
from flexsheet.experiments import fem as F  # noqa: E402
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache  # noqa: E402
from nodes.fem.snapshots import DEFAULT_REF_SPEC, SnapshotGrid, SnapshotModel  # noqa: E402

if __name__ == "__main__":
    h = float(sys.argv[1]) * 1e-3 if len(sys.argv) > 1 else 0.0045
    a0, a1, amid = (float(x) for x in sys.argv[2:5]) if len(sys.argv) > 4 else (7.5, 10.0, 8.75)
    mat = F.DEFAULT_MATERIAL
    cache = ArrayCache(DEFAULT_CACHE_DIR, F._log)
    st0 = F.settings_for(False)
    rm = F.realtime_model(st0, mat, DEFAULT_CACHE_DIR)
    verts = rm.rest_vertices.astype(float)
    spec = replace(DEFAULT_REF_SPEC, h_fine=h)
    step = 0.0025
    depths = F._depths(step)
    laws = ("frictionless", "sticking")
    work = [(i, F.Solve(spec, a, step, stable=(c == "frictionless")), mat, cache.cache_dir, verts, c)
            for i, (c, a) in enumerate((c, a) for c in laws for a in (a0, a1, amid))]
    t0 = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(2, initializer=F._solver_init, initargs=(ctx.Value("i", 0),)) as pool:
        for i, sec, err in pool.imap_unordered(F._solve_one, work):
            F._log(f"probe: {work[i][5]} at {work[i][1].angle_deg:g} deg done in {sec:.0f} s"
                   + (f" FAILED: {err}" if err else ""))

    def path(a, c):
        solve = F.stable_path if c == "frictionless" else F.reference_path
        return solve(spec, a, depths, mat, cache, verts, c)

    out = {"what": __doc__.split("\n\n")[1].replace("\n", " "), "mesh": spec.__dict__,
           "azimuths_deg": [a0, a1], "held_out_deg": amid, "depths_mm": (depths * 1e3).tolist(),
           "solve_wall_s": time.perf_counter() - t0, "laws": {}}
    fixed = rm.mesh.fixed[rm.surface_nodes]
    for c in laws:
        paths = {a: path(a, c) for a in (a0, a1, amid)}
        st = replace(st0, grid=SnapshotGrid(angles_deg=(a0, a1)), snap_spec=spec, contact=c)

        def solved(ang, model, ds, c=c):
            return F._path_states(path(ang, c), depths, ds, model)

        table, _, _ = F.snapshot_table(st, mat, cache, solved)
        keep = rm.snapshots
        try:
            rm.snapshots = SnapshotModel(table, verts, E=mat.E)
            cases = [{"angle_deg": amid, "depth": float(d), "u": paths[amid]["u"][j]} for j, d in enumerate(depths)]
            err = [e * 1e3 for e in F.errors(rm, cases, "snapshots")]
        finally:
            rm.snapshots = keep
        out["laws"][c] = {
            "held_out_error_mm": err, "max_held_out_error_mm": max(err),
            "over_target_from_mm": next((float(d) * 1e3 for d, e in zip(depths, err) if e > 0.7), None),
            "paths": {f"{a:g}": {"dofs": int(p["dofs"]), "cpu_seconds": float(p["cpu_seconds"]),
                                 "newton_converged": bool(np.all(p["converged"])),
                                 "converged_to_mm": float(depths[np.argmin(p["converged"])] * 1e3)
                                 if not np.all(p["converged"]) else 50.0,
                                 "force_N": np.asarray(p["force"]).tolist(),
                                 "unloaded_state_at_mm": (depths[np.asarray(p["branch"]) == 1] * 1e3).tolist()
                                 if "branch" in p else None}
                      for a, p in paths.items()}}
        F._log(f"probe {c}: held out {amid:g} deg from [{a0:g}, {a1:g}]: worst {max(err):.2f} mm")
    out["law_difference_mm"] = {
        f"{a:g}": [e * 1e3 for e in F._visible_diffs(path(a, "sticking"), path(a, "frictionless"), depths, verts,
                                                     fixed, rm.mesh, a)] for a in (a0, a1, amid)}
    json.dump(out, open("contact_probe.json", "w"), indent=1)
    F._log("probe -> contact_probe.json")
