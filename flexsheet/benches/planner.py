"""``flexsheet bench planner``: time one planner update (pure path: projection, rolling, tension, limits,
reach) per shape, and the shape queries alone. Prints medians in µs; ``--json`` prints one JSON object
with ``update_median_us`` (the paper's cylinder) and per-shape figures."""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

from flexsheet.model.shapes import MeshShape, make_shape
from flexsheet.planning.surface_planner import SurfacePlanner

__all__ = ["measure", "main"]


def measure(shape_kind: str = "cylinder", n: int = 2000) -> dict[str, float]:
    """Median and p95 µs of :meth:`SurfacePlanner.update` over ``n`` samples of a 48 Hz stroke on
    ``shape_kind`` (a mesh uses a trimesh icosphere), plus the median of ``Shape.project`` alone."""
    if shape_kind == "mesh":
        import trimesh

        shape = MeshShape(trimesh.creation.icosphere(3, radius=0.035), translation=(-0.035, 0.0, 0.0))
        n = min(n, 200)
    else:
        shape = make_shape(shape_kind)
    pl = SurfacePlanner(shape)
    R = 0.0354
    pts = []
    for k in range(n):
        a = math.radians(60.0) * k / n
        pts.append((-R + R * math.cos(a), 0.01 * math.sin(k / 50.0), R * math.sin(a)))
    times = []
    for k, p in enumerate(pts):
        t0 = time.perf_counter_ns()
        pl.update(k / 48.0, p)
        times.append((time.perf_counter_ns() - t0) / 1e3)
    proj = []
    for p in pts[: min(n, 500)]:
        t0 = time.perf_counter_ns()
        shape.project(p)
        proj.append((time.perf_counter_ns() - t0) / 1e3)
    times.sort()
    return {"update_median_us": statistics.median(times),
            "update_p95_us": times[int(0.95 * (len(times) - 1))],
            "project_median_us": statistics.median(proj), "n": n}


def main(argv: list[str] | None = None) -> int:
    """CLI entry: ``flexsheet bench planner [--json] [--n N]``. Returns 0."""
    ap = argparse.ArgumentParser(prog="flexsheet bench planner", description=__doc__.split("\n")[0],
                                 epilog="example: flexsheet bench planner --json")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--n", type=int, default=2000, help="updates per shape (default 2000)")
    a = ap.parse_args(argv)
    if a.n < 10:
        ap.error(f"--n must be >= 10, got {a.n}")
    res = {k: measure(k, a.n) for k in ("cylinder", "sphere", "box", "plane", "mesh")}
    out = {"update_median_us": res["cylinder"]["update_median_us"], "target_us": 50.0, "shapes": res}
    if a.json:
        print(json.dumps(out))
    else:
        for k, r in res.items():
            print(f"{k:9s} update median {r['update_median_us']:7.1f} µs  p95 {r['update_p95_us']:7.1f} µs  "
                  f"project {r['project_median_us']:6.1f} µs")
        print(f"update_median_us (cylinder) = {out['update_median_us']:.1f} (target <= 50)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
