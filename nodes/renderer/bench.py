"""``flexsheet bench render``: time to correct and draw one stereo pair (2 × 1024 × 768) per correction model.

The time covers setting the sheet uniforms (the CPU part of the correction: triangle normals, membrane
coefficients), drawing both eyes with the per-vertex correction in the vertex shader, and ``ctx.finish()``;
read-back is reported separately (``readback_ms``). Figures on a shared CPU (llvmpipe) are pessimistic.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np

from flexsheet.model import scene
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import Membrane, SheetSurface
from nodes.renderer.scene import StereoRenderer, cylinder_mesh

__all__ = ["main", "time_models", "bench_sheets"]


def bench_sheets(depth: float = 0.03, theta_deg: float = 30.0, fine_modes: int = 16) -> dict[str, SheetSurface]:
    """Representative sheet per model: tilted plane for ``flat``, centre push of ``depth`` m otherwise."""
    R = scene.CYLINDER_RADIUS
    th = np.radians(theta_deg)
    tilt = SheetSurface([-R + R * np.cos(th), 0.0, -R * np.sin(th)], [np.cos(th), 0.0, -np.sin(th)], [0, 1, 0])
    pushed = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0],
                          membrane=Membrane(0.12, 0.12, 0.0, 0.0, depth, modes=fine_modes))
    return {"none": tilt, "flat": tilt, "four_triangle": pushed, "fine": pushed}


def time_models(renderer: StereoRenderer, repeats: int = 20, models=("none", "flat", "four_triangle", "fine"),
                sheets: dict | None = None) -> dict[str, dict[str, float]]:
    """Median/p90 ms per stereo pair for each model on ``renderer`` (its mesh must be set)."""
    sheets = sheets or bench_sheets()
    out = {}
    for model in models:
        renderer.set_model(model, sheets[model])
        renderer.render_pair()                               # warm-up (shader compile paths)
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            renderer.set_model(model, sheets[model])
            renderer.render_pair()
            ts.append((time.perf_counter() - t0) * 1e3)
        ts.sort()
        out[model] = {"median_ms": statistics.median(ts), "p90_ms": ts[int(0.9 * (len(ts) - 1))]}
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``flexsheet bench render``; returns the exit code."""
    ap = argparse.ArgumentParser(
        prog="flexsheet bench render", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: flexsheet bench render --json --repeats 30")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--repeats", type=int, default=30, help="timed pairs per model (default 30)")
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=768)
    ap.add_argument("--model", default="four_triangle", help="model whose time is stereo_pair_ms")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    r = StereoRenderer(Projector.default(args.width, args.height))
    v, f = cylinder_mesh()
    r.set_mesh(v, f)
    per = time_models(r, args.repeats)
    t0 = time.perf_counter()
    for _ in range(5):
        r.read_pair()
    readback = (time.perf_counter() - t0) / 5 * 1e3
    res = {
        "stereo_pair_ms": per[args.model]["median_ms"],
        "model": args.model,
        "per_model": per,
        "readback_ms": readback,
        "size": [args.width, args.height],
        "vertices": int(len(v)),
        "triangles": int(len(f)),
        "gl_renderer": r.ctx.info.get("GL_RENDERER", "?"),
        "target_ms": 1000.0 / 120.0,
    }
    if args.json:
        print(json.dumps(res))
    else:
        print(f"renderer {res['gl_renderer']}, {args.width}x{args.height} per eye, {len(v)} vertices")
        for m, d in per.items():
            print(f"  {m:14s} stereo pair {d['median_ms']:7.2f} ms (p90 {d['p90_ms']:.2f})")
        print(f"  read-back of the pair {readback:.2f} ms; target {res['target_ms']:.2f} ms (120 Hz)")
    r.release()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
