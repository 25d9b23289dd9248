"""The speed of each correction model: :func:`model_speed`, milliseconds per stereo pair as the node draws."""

from __future__ import annotations

import numpy as np

from flexsheet.benches.render import time_models
from flexsheet.experiments.correction.poses import inclined_pose
from flexsheet.experiments.correction.settings import STRETCH
from flexsheet.model.sheet import Membrane, SheetSurface, clamp_half_span
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh


def model_speed(sheet_model=None, repeats: int = 10) -> dict:
    """Median ms per 2×1024×768 stereo pair (shaded, no MSAA, as the node draws) per model on the nominal
    projector: none, flat, four_triangle, fine (16-mode series) and, with ``sheet_model``, fine with its
    gripped sheet's FEM depth table; plus the GL renderer's name."""
    a = clamp_half_span(STRETCH)
    home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], a)
    tilt = SheetSurface(*inclined_pose(30))
    series = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], a,
                          membrane=Membrane(a, 0.12, 0.0, 0.0, 0.03, modes=16))
    rt = StereoRenderer()
    v, f = cylinder_draw_mesh()
    rt.set_mesh(v, f)
    t = time_models(rt, repeats, sheets={"none": home, "flat": tilt, "four_triangle": series, "fine": series})
    out = {m: d["median_ms"] for m, d in t.items()}
    if sheet_model is not None:
        fem = sheet_model.surface(series)
        out["fem_nominal"] = time_models(rt, repeats, models=("fine",),
                                         sheets={"fine": fem})["fine"]["median_ms"]
    out["gl_renderer"] = rt.ctx.info.get("GL_RENDERER", "?")
    rt.release()
    return out
