"""The renderer's pure timings for ``flexsheet bench render`` and ``flexsheet experiment correction --speed``:
one corrected stereo pair per correction model (offscreen, EGL), and the pushed-sheet shape per frame."""

from __future__ import annotations

import statistics
import time

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.model.sheet_model import SheetConfig, sheet_model_for
from flexsheet.rendering.state import RendererState
from flexsheet.rendering.stereo_renderer import StereoRenderer

__all__ = ["BENCH_STRETCH", "bench_sheets", "sheet_update", "time_models"]

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
