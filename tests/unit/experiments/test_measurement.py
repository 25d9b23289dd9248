"""The measurement camera (flexsheet.experiments.measurement): projector pixels as OpenCV projects them, the
flat correction within a pixel on its photographs."""

import cv2
import numpy as np
import pytest
from test_stereo_renderer import sheets

from flexsheet.experiments.measurement import MeasurementCamera, measure_sizes, projector_pixels
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh

R = geometry.CYLINDER_RADIUS


def test_projector_pixels_match_opencv():
    p = Projector.default()
    D = np.array([-0.02, 0.01, 0.001, -0.0015, 0.003])
    X = np.random.default_rng(3).normal(size=(40, 3)) * 0.1
    uv, front = projector_pixels(X, p, D)
    ref = cv2.projectPoints(X, cv2.Rodrigues(p.R.T)[0], -p.R.T @ p.position, p.K, D)[0].reshape(-1, 2)
    assert front.all() and np.abs(uv - ref).max() < 1e-9
    with pytest.raises(ValueError, match="distortion"):
        projector_pixels(X, p, [0.1, 0.2])


def test_measurement_camera_flat_correction_within_a_pixel():
    r = StereoRenderer(samples=4, shading=False)
    try:
        v, f = cylinder_draw_mesh()
        r.set_mesh(v, f)
        cam = MeasurementCamera(pixel=0.0007, extent=(0.2, 0.16))
        home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])
        r.set_model("none")
        proper = measure_sizes(cam.photograph(r.render_single(geometry.EYE), r.projector, home), cam.pixel)
        # independent geometry: width 120 mm at the middle row, silhouette height from the eye
        assert abs(proper["w"] - 0.120) < 0.0007
        h = 2 * 0.4 * R / np.sqrt((0.4 + R) ** 2 - R**2)
        assert abs(proper["h"] - h) < 0.0007
        tilt, push = sheets()
        shot = {}
        for model in ("none", "flat"):
            r.set_model(model, tilt)
            shot[model] = measure_sizes(cam.photograph(r.render_single(geometry.EYE), r.projector, tilt),
                                        cam.pixel)
        err = {m: np.mean([abs(shot[m][k] - proper[k]) for k in "hud"]) for m in shot}
        assert err["none"] > 0.005           # uncorrected: several mm off at 40°
        assert err["flat"] < 0.0007          # corrected: within one projector pixel
    finally:
        r.release()
