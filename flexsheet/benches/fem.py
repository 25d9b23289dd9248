"""``flexsheet bench fem [--json] [--out DIR]``: speed of the FEM node's model on this machine.

Times, for the model the node would choose (accuracy table, default params): start-up precompute without a
cache, start-up with a cache hit, the condensed (capacitance) update including surface vertices and failure
checks at 5 and 30 mm push (median and 90th percentile over ``--n`` updates), the full sparse baseline, and
one corotational solve. No assertions: figures only (a shared machine gives pessimistic numbers).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import numpy as np

from flexsheet.fem.choose import choose, load_table
from flexsheet.fem.contact import finger_at
from flexsheet.fem.corotational import solve_corotational
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.solver import FemModel, solve_full

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures (JSON with ``--json``); returns 0."""
    ap = argparse.ArgumentParser(prog="flexsheet bench fem", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet bench fem --json")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--n", type=int, default=1000, help="updates per depth (default %(default)s)")
    ap.add_argument("--out", default="", help="also write DIR/bench.json")
    args = ap.parse_args(argv)
    mat = Material()
    ch = choose(load_table(), 0.0007, 0.005, 0.03, mat.nu, 0.008)
    res = {"choice": ch.reason, "order": ch.order, "mesh": ch.spec.__dict__}
    with tempfile.TemporaryDirectory() as cache:
        t = time.perf_counter()
        rm = RealtimeModel(ch.spec, mat, cache_dir=cache, order=ch.order)
        res["precompute_s"] = time.perf_counter() - t
        t = time.perf_counter()
        rm2 = RealtimeModel(ch.spec, mat, cache_dir=cache, order=ch.order)
        res["startup_cache_hit_s"] = time.perf_counter() - t
        res["cache_hit"] = rm2.cache_hit
    res["mesh_nodes"] = rm.n_nodes
    res["dofs"] = rm.model.n_dofs
    res["surface_vertices"] = len(rm.surface_nodes)
    res["precomputed_MB"] = rm.solver.nbytes / 1e6
    for d in (0.005, 0.03):
        fg = finger_at(0.0, d, 0.008, rm.mesh.radius, rm.mesh.center)
        rm.update_finger(fg)
        ts = np.empty(args.n)
        for i in range(args.n):
            t = time.perf_counter()
            rm.update_finger(fg)
            ts[i] = time.perf_counter() - t
        key = f"{d * 1e3:.0f}mm"
        res[f"update_ms_median_{key}"] = float(np.median(ts) * 1e3)
        res[f"update_ms_p90_{key}"] = float(np.percentile(ts, 90) * 1e3)
        res[f"update_hz_{key}"] = float(1.0 / np.median(ts))
        t = time.perf_counter()
        solve_full(rm.model, fg)
        res[f"sparse_ms_{key}"] = (time.perf_counter() - t) * 1e3
    p1 = FemModel(rm.mesh, mat, order=1)
    t = time.perf_counter()
    _, it, conv = solve_corotational(p1, finger_at(0.0, 0.01, 0.008, rm.mesh.radius, rm.mesh.center))
    res["corotational_ms_10mm"] = (time.perf_counter() - t) * 1e3
    res["corotational_iterations_10mm"] = it
    res["corotational_converged_10mm"] = conv
    res["note"] = "shared 2-core machine: pessimistic; median is the figure against the 1 ms target"
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "bench.json"), "w") as fh:
            json.dump(res, fh, indent=1)
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        for k, v in res.items():
            print(f"{k:32s} {v:.4g}" if isinstance(v, float) else f"{k:32s} {v}")
    return 0
