"""``flexsheet bench render``: time to correct and draw one stereo pair (2 × 1024 × 768) per correction model,
and the per-frame cost of the pushed sheet's shape (``sheet_update``: the node's :class:`RendererState`
turning a new fingertip into the depth table the fine shader draws); with ``--window``, the projector
window's frame pacing.

The time covers setting the sheet uniforms (the CPU part of the correction: triangle normals, membrane depth
table texture), drawing both eyes with the per-vertex correction in the vertex shader, and ``ctx.finish()``;
read-back is reported separately (``readback_ms``). Figures on a shared CPU (llvmpipe) are pessimistic.
:func:`time_models` and :func:`sheet_update` are shared with ``flexsheet experiment correction --speed``.

``--window`` opens the projector window (the projector output port's ``window``,
:mod:`flexsheet.rendering.output_port`; on a private Xvfb, :mod:`flexsheet.benches.xvfb`, with ``--xvfb`` or
when ``DISPLAY`` is unset) and presents frames for ``--seconds`` in the ``--stereo`` format at
``--refresh-hz``, twice: present only (the pair drawn once), then redrawing the pair at ``--redraw-hz``
(alternating two sheets, as new fingertips would). It reports the interval between swaps (mean, p99), the
frame rate, missed vsyncs, eye resyncs, and whether swaps waited for the display (``pacing``: "vsync") or a
timer paced them ("timer": Xvfb has no vsync).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import sys
import threading
import time

import numpy as np

from flexsheet.benches.xvfb import xvfb
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.scenes import load_scene
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.model.sheet_model import SheetConfig, sheet_model_for
from flexsheet.rendering.output_port import projector_output
from flexsheet.rendering.pacing import FramePacer
from flexsheet.rendering.state import RendererState
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh

log = logging.getLogger(__name__)

__all__ = ["BENCH_STRETCH", "bench_sheets", "sheet_update", "time_models", "window_pacing", "main"]

#: clamp stretch of the benches' pushed sheet (the planner's for the default object; a cached table node)
BENCH_STRETCH = 0.04


def bench_sheets(depth: float = 0.03, theta_deg: float = 30.0, sheet_model=None) -> dict[str, SheetSurface]:
    """Representative sheet per model: tilted plane for ``flat``, centre push of ``depth`` m otherwise, shaped
    by the renderer's pushed-sheet model (``sheet_model``; default the node's, its table built if missing)."""
    R = geometry.CYLINDER_RADIUS
    th = np.radians(theta_deg)
    tilt = SheetSurface([-R + R * np.cos(th), 0.0, -R * np.sin(th)], [np.cos(th), 0.0, -np.sin(th)],
                        [0, 1, 0])
    flat = SheetSurface.from_clamps(*clamp_poses(np.zeros(3), [1, 0, 0], [0, 1, 0], BENCH_STRETCH))
    pushed = (sheet_model or sheet_model_for()).pushed(flat, np.array([-depth, 0.0, 0.0]))
    return {"none": tilt, "flat": tilt, "four_triangle": pushed, "fine": pushed}


def sheet_update(frames: int = 200, sheet_model=None) -> dict[str, float]:
    """Per-frame cost (ms) of the node's sheet for a moving finger: :meth:`RendererState.sheet_for_frame` with
    a new fingertip every frame (depth 10→50 mm and contact sweeping ±30 mm, so every frame misses the depth
    table's cache: the FEM tables on the depth table's grid), and with the same fingertip (cache hit). Wall
    times, plus the drawing thread's own CPU time per new fingertip (``new_finger_cpu_median_ms``: what the
    frame costs without other processes competing for the cores)."""
    st = RendererState(geometry.EYE, geometry.PROJECTOR, SheetConfig(),
                       sheet_model=sheet_model or sheet_model_for())
    for side, T in zip(("left", "right"), clamp_poses(np.zeros(3), [1, 0, 0], [0, 1, 0], BENCH_STRETCH),
                       strict=True):
        st.set_arm_pose(side, T)
    st.set_fingertip(np.array([-0.03, 0.0, 0.0]), 0.0)
    st.sheet_for_frame()                                         # loads the table
    miss, hit, cpu = [], [], []
    for k in range(frames):
        x = k / max(frames - 1, 1)
        st.set_fingertip(np.array([-0.01 - 0.04 * x, 0.03 * np.sin(7 * x), 0.03 * np.cos(5 * x)]), 0.0)
        t0, c0 = time.perf_counter(), time.thread_time()
        st.sheet_for_frame()
        miss.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.thread_time() - c0) * 1e3)
        t0 = time.perf_counter()
        st.sheet_for_frame()
        hit.append((time.perf_counter() - t0) * 1e3)
    miss.sort()
    hit.sort()
    return {"frames": frames, "new_finger_median_ms": statistics.median(miss),
            "new_finger_p90_ms": miss[int(0.9 * (frames - 1))], "new_finger_max_ms": miss[-1],
            "new_finger_cpu_median_ms": statistics.median(cpu),
            "same_finger_median_ms": statistics.median(hit)}


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


def window_pacing(seconds: float = 5.0, *, stereo: str = "frame_sequential", refresh_hz: float | None = 120.0,
                  redraw_hz: float = 30.0, width: int = 1024, height: int = 768,
                  model: str = "four_triangle") -> dict:
    """Frame pacing of the projector window (see the module docstring); run it on a thread with no current
    EGL context. Returns {"present_only": stats, "with_redraws": stats, ...} (times in ms)."""
    out = projector_output("window")(Projector.default(width, height), stereo=stereo, refresh_hz=refresh_hz,
                                     fullscreen=False)
    try:
        r = out.renderer
        v, f = cylinder_draw_mesh()
        r.set_mesh(v, f)
        sheets = bench_sheets()
        other = bench_sheets(depth=0.02)
        r.set_model(model, sheets[model])
        r.render_pair()
        res = {"stereo": stereo, "size_per_eye": [width, height],
               "frame_size": list(out.presenter.frame_size),
               "refresh_hz": out.window.refresh_hz, "pacing": out.window.pacing,
               "quad_buffered": out.window.quad_buffered, "monitor": out.window.monitor_name,
               "gl_renderer": r.ctx.info.get("GL_RENDERER", "?"), "redraw_hz": redraw_hz, "model": model,
               "seconds_per_phase": seconds}
        for phase, rate in (("present_only", 0.0), ("with_redraws", redraw_hz)):
            out.pacer = FramePacer(out.window.refresh_hz)
            draw_ms, present_ms = [], []
            t_end = time.perf_counter() + seconds
            last_draw, k = 0.0, 0
            while time.perf_counter() < t_end:
                now = time.perf_counter()
                if rate > 0 and now - last_draw >= 1.0 / rate:
                    last_draw, k = now, k + 1
                    r.set_model(model, (sheets if k % 2 else other)[model])
                    r.render_pair()
                    draw_ms.append((time.perf_counter() - now) * 1e3)
                t0 = time.perf_counter()
                out.presenter.draw(out.pacer.next_eye() if stereo == "frame_sequential" else 0)
                r.ctx.finish()                          # present cost, apart from the wait for the vsync
                present_ms.append((time.perf_counter() - t0) * 1e3)
                t, msc = out.window.swap()
                out.pacer.on_swap(t, msc)
                out.window.poll(keep_open=True)
            st = out.pacer.stats()
            res[phase] = {"frames": st.frames, "fps": st.fps, "interval_mean_ms": st.interval_mean_ms,
                          "interval_p99_ms": st.interval_p99_ms, "missed_vsyncs": st.missed_vsyncs,
                          "eye_resyncs": st.eye_resyncs, "redraws": len(draw_ms),
                          "redraw_median_ms": statistics.median(draw_ms) if draw_ms else 0.0,
                          "present_median_ms": statistics.median(present_ms)}
            log.info(f"{phase}: {st.line()}")
        return res
    finally:
        out.close()


def _window_main(args) -> dict:
    """Run :func:`window_pacing` on a thread of its own, on a private Xvfb if asked or if there is no
    DISPLAY."""
    def run(display: str) -> dict:
        os.environ["DISPLAY"] = display
        box: dict = {}

        def target():
            try:
                box["res"] = window_pacing(args.seconds, stereo=args.stereo, refresh_hz=args.refresh_hz,
                                           redraw_hz=args.redraw_hz, width=args.width, height=args.height,
                                           model=args.model)
            except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
                box["err"] = exc

        th = threading.Thread(target=target, name="bench-window")
        th.start()
        th.join()
        if "err" in box:
            raise box["err"]
        box["res"]["display"] = display + (" (private Xvfb)" if xvfb_used else "")
        return box["res"]

    xvfb_used = args.xvfb or not os.environ.get("DISPLAY")
    if xvfb_used:
        with xvfb(max(1280, 2 * args.width), max(1024, 2 * args.height)) as d:
            return run(d)
    return run(os.environ["DISPLAY"])


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="flexsheet bench render", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples: flexsheet bench render --json --repeats 30\n"
               "          flexsheet bench render --scene launch/scenes/organ.yaml --repeats 10\n"
               "          flexsheet bench render --window --xvfb --seconds 5 --json")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--repeats", type=int, default=30, help="timed pairs per model (default 30)")
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=768)
    ap.add_argument("--model", default="four_triangle", help="model whose time is stereo_pair_ms")
    ap.add_argument("--scene", default=None, help="scene file whose object is drawn (default: the paper's "
                                                  "cylinder)")
    ap.add_argument("--window", action="store_true", help="measure the projector window's frame pacing "
                                                          "instead")
    ap.add_argument("--xvfb", action="store_true", help="--window on a private Xvfb (default when DISPLAY is "
                                                        "unset)")
    ap.add_argument("--seconds", type=float, default=5.0, help="--window: seconds per phase (default 5)")
    ap.add_argument("--stereo", default="frame_sequential",
                    choices=["frame_sequential", "side_by_side", "top_bottom", "mono"],
                    help="--window: format")
    ap.add_argument("--refresh-hz", type=float, default=120.0, help="--window: refresh to ask for (default "
                                                                    "120)")
    ap.add_argument("--redraw-hz", type=float, default=30.0,
                    help="--window: pair redraws per s in the second phase (default 30, as sim.yaml)")
    return ap


def _window_report(ap: argparse.ArgumentParser, args) -> int:
    """``--window``: measure the window's frame pacing and print it."""
    if args.seconds <= 0 or args.refresh_hz <= 0 or args.redraw_hz <= 0:
        ap.error("--seconds, --refresh-hz and --redraw-hz must be > 0")
    res = _window_main(args)
    if args.json:
        print(json.dumps(res))
    else:
        print(f"window {res['frame_size'][0]}x{res['frame_size'][1]} {res['stereo']} on {res['display']}, "
              f"{res['gl_renderer']}, asked {res['refresh_hz']:g} Hz, pacing {res['pacing']}")
        for ph in ("present_only", "with_redraws"):
            d = res[ph]
            print(f"  {ph:13s} {d['fps']:6.1f} fps, interval mean {d['interval_mean_ms']:.2f} ms p99 "
                  f"{d['interval_p99_ms']:.2f} ms, missed vsyncs {d['missed_vsyncs']} of {d['frames']} "
                  f"frames, eye resyncs {d['eye_resyncs']}, redraw {d['redraw_median_ms']:.1f} ms, present "
                  f"{d['present_median_ms']:.2f} ms")
    return 0


def _print_render(res: dict, args, per: dict, readback: float, sheet_ms: dict, n_vertices: int) -> None:
    """The figures of the correction models and the sheet update, as text."""
    print(f"renderer {res['gl_renderer']}, {args.width}x{args.height} per eye, {n_vertices} vertices")
    for m, d in per.items():
        print(f"  {m:14s} stereo pair {d['median_ms']:7.2f} ms (p90 {d['p90_ms']:.2f})")
    print(f"  read-back of the pair {readback:.2f} ms; target {res['target_ms']:.2f} ms (120 Hz)")
    print(f"  pushed-sheet shape per frame (RendererState, gripped FEM depth table): new fingertip "
          f"{sheet_ms['new_finger_median_ms']:.2f} ms median (p90 {sheet_ms['new_finger_p90_ms']:.2f}, max "
          f"{sheet_ms['new_finger_max_ms']:.2f}; CPU {sheet_ms['new_finger_cpu_median_ms']:.2f}), same "
          f"fingertip {sheet_ms['same_finger_median_ms']:.3f} ms")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``flexsheet bench render``; returns the exit code."""
    ap = _parser()
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    if args.window:
        return _window_report(ap, args)
    if args.scene:
        try:
            v, f = load_scene(args.scene).surface_mesh()
        except ValueError as exc:
            ap.error(str(exc))
    else:
        v, f = cylinder_draw_mesh()
    r = StereoRenderer(Projector.default(args.width, args.height))
    r.set_mesh(v, f)
    model = sheet_model_for()
    per = time_models(r, args.repeats, sheets=bench_sheets(sheet_model=model))
    sheet_ms = sheet_update(sheet_model=model)
    t0 = time.perf_counter()
    for _ in range(5):
        r.read_pair()
    readback = (time.perf_counter() - t0) / 5 * 1e3
    res = {
        "stereo_pair_ms": per[args.model]["median_ms"],
        "model": args.model,
        "per_model": per,
        "readback_ms": readback,
        "sheet_update": sheet_ms,
        "size": [args.width, args.height],
        "scene": args.scene or "cylinder (paper)",
        "vertices": int(len(v)),
        "triangles": int(len(f)),
        "gl_renderer": r.ctx.info.get("GL_RENDERER", "?"),
        "target_ms": 1000.0 / 120.0,
    }
    if args.json:
        print(json.dumps(res))
    else:
        _print_render(res, args, per, readback, sheet_ms, len(v))
    r.release()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
