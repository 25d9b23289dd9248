"""The measurement camera's photographs: :class:`Measurer`, the camera at the paper's viewpoint V and the
proper image's sizes."""

from __future__ import annotations

import numpy as np

from flexsheet.experiments.correction.twin_world import TwinWorld
from flexsheet.experiments.measurement import MeasurementCamera, measure_edges, measure_sizes
from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh


class Measurer:
    """The measurement camera (:class:`flexsheet.experiments.measurement.MeasurementCamera`) at the paper's
    viewpoint V, and the proper image's sizes (the cylinder's perspective image on the imaginary screen, drawn
    by a nominal pinhole projector onto the screen itself: no correction is involved, so any projector gives
    it up to pixel sampling). ``pixel`` m per camera pixel on the screen."""

    def __init__(self, pixel: float = 0.00035) -> None:
        self.cam = MeasurementCamera(pixel=pixel, extent=(0.26, 0.22))
        r = StereoRenderer(samples=4, shading=False)
        v, f = cylinder_draw_mesh()
        r.set_mesh(v, f)
        home = SheetSurface(np.zeros(3), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        with r.ctx:
            self.proper_photo = self.cam.photograph(r.render_single(geometry.EYE), r.projector, home)
        r.release()
        self.proper = self.sizes(self.proper_photo)
        self.proper_centre = self.centre(self.proper_photo)

    def sizes(self, photo) -> dict[str, float]:
        """Sizes (mm) of a photograph."""
        return {k: v * 1e3 for k, v in measure_sizes(photo, self.cam.pixel).items()}

    def centre(self, photo) -> np.ndarray:
        """Centre (mm, right/up on the screen) of the object's h and w spans."""
        e = measure_edges(photo, self.cam.pixel)
        return np.array([0.5 * (e["left"] + e["right"]), 0.5 * (e["top"] + e["bottom"])]) * 1e3

    def shoot(self, image, world: TwinWorld, true_sheet: SheetSurface) -> np.ndarray:
        """Photograph of the projector ``image`` lit by the true projector onto ``true_sheet``."""
        return self.cam.photograph(image, world.projector, true_sheet, distortion=world.distortion)

    def errors(self, photo, keys: str) -> dict:
        """{"mean_mm", "sizes_mm": {k: |size − proper|}, "position_mm"} of a photograph."""
        s = self.sizes(photo)
        d = {k: abs(s[k] - self.proper[k]) for k in keys}
        pos = float(np.linalg.norm(self.centre(photo) - self.proper_centre))
        return {"mean_mm": float(np.mean(list(d.values()))), "sizes_mm": d, "position_mm": pos}
