"""The renderer draws any scene through the registered projector.

The expected images are computed here from first principles — the sphere's silhouette seen from the eye (its
tangent cone) cut by the imaginary screen, mapped to projector pixels with a numpy pinhole (or
``cv2.projectPoints``) from the ``Projector``'s K, R, P — never from the renderer's own code.
"""

from __future__ import annotations

import asyncio
import math

import cv2
import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from flexsheet.calibration.display_calib import (
    DisplayCalib,
    ProjectorEntry,
    Provenance,
    nominal_display_calib,
    pose_from_rt,
)
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.model import geometry as paper
from flexsheet.model.projector import Projector
from flexsheet.model.scenes import SCENES_DIR, load_scene
from flexsheet.rendering.state import load_geometry
from flexsheet.rendering.stereo_renderer import StereoRenderer, scaled_projector
from flexsheet.runtime.testing import NodeHarness
from messages import topics
from nodes.renderer.node import RendererNode

W, H = 512, 384                                       # half the projector's 1024 x 768: 1.4 mm per pixel
SPHERE = str(SCENES_DIR / "sphere.yaml")


def pixels(K, R, P, X, full=(1024, 768)) -> np.ndarray:
    """Pinhole: display points X (N, 3) → pixels (N, 2) of the full-size projector, then of the W x H image
    (pixel centres at integers: u' = (u + ½)·W/1024 − ½)."""
    pc = (np.asarray(X, float) - P) @ R
    uv = (pc @ np.asarray(K).T)[:, :2] / pc[:, 2:3]
    return (uv + 0.5) * np.array([W / full[0], H / full[1]]) - 0.5


def sphere_outline(eye, c, r, n=720) -> np.ndarray:
    """Where the sphere's silhouette (tangent cone from ``eye``) meets the imaginary screen x = 0, (n, 3)."""
    a = c - eye
    d = np.linalg.norm(a)
    a = a / d
    alpha = math.asin(r / d)
    u = np.cross(a, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    w = np.cross(a, u)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    dirs = math.cos(alpha) * a + math.sin(alpha) * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * w)
    s = -eye[0] / dirs[:, 0]
    return eye + s[:, None] * dirs


def expected_mask(K, R, P, eye=paper.EYE) -> np.ndarray:
    sc = load_scene(SPHERE)
    uv = pixels(K, R, P, sphere_outline(np.asarray(eye, float), sc.center, sc.object.radius))
    yy, xx = np.mgrid[0:H, 0:W]
    inside = MplPath(uv).contains_points(np.column_stack([xx.ravel(), yy.ravel()]))
    return inside.reshape(H, W)


def centroid(mask) -> np.ndarray:
    yy, xx = np.nonzero(mask)
    return np.array([xx.mean(), yy.mean()])


def iou(a, b) -> float:
    return float((a & b).sum() / (a | b).sum())


def render(params: dict) -> tuple[np.ndarray, RendererNode]:
    base = {"width": W, "height": H, "stereo": "mono", "publish_scale": 1.0, "publish_rate": 30.0}

    async def scenario():
        async with NodeHarness(RendererNode, params={**base, **params}) as h:
            m = (await h.wait_for(topics.RENDERED, n=2, timeout=20.0))[-1]
            assert h.rejected() == 0 and m.correction == "flat"      # the home sheet: flat is exact
            assert np.abs(m.left.astype(int) - m.right).max() <= 2  # mono: both eyes at V
            return m.left, h.node

    return asyncio.run(scenario())


@pytest.fixture(scope="module")
def nominal_frames():
    sphere, node = render({"scene": SPHERE})
    assert node.geometry.nominal and node.geometry.scene.name == "sphere"
    cyl, node = render({})
    assert node.geometry.scene.name == "cylinder"                   # the default scene
    return sphere.max(axis=2) > 30, cyl.max(axis=2) > 30


def test_sphere_scene_is_drawn_where_the_projector_geometry_says(nominal_frames):
    sphere, cyl = nominal_frames
    p = Projector.default()
    want = expected_mask(p.K, p.R, p.position)
    assert want.sum() > 1000                                        # ~23 px radius
    assert iou(sphere, want) > 0.97
    assert np.linalg.norm(centroid(sphere) - centroid(want)) < 0.3
    # the cylinder scene draws another object: a 120 mm long bar, wider than the sphere
    assert (sphere ^ cyl).sum() > 0.3 * (sphere | cyl).sum()
    assert np.ptp(np.nonzero(cyl)[1]) > 1.5 * np.ptp(np.nonzero(sphere)[1])


def test_projector_of_display_yaml_moves_the_image(tmp_path, nominal_frames):
    sphere_nominal, _ = nominal_frames
    cal = nominal_display_calib()
    pe = cal.projector
    K = pe.K.copy()
    K[0, 2] += 12.0                                                 # lens shift, px
    K[1, 1] *= 1.03
    c, s = math.cos(math.radians(2.0)), math.sin(math.radians(2.0))
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ pe.T_display_projector[:3, :3]
    P = pe.position + np.array([0.0, 0.03, -0.02])
    cal.projector = ProjectorEntry(K, np.zeros(5), pose_from_rt(R, P), pe.width, pe.height,
                                   Provenance("test: moved projector", source="lab", n_poses=3))
    path = tmp_path / "display.yaml"
    write_display_calib(str(path), cal)
    img, node = render({"scene": SPHERE, "display_calib": str(path)})
    assert not node.geometry.nominal
    got = img.max(axis=2) > 30
    p0 = Projector.default()
    want0, want = expected_mask(p0.K, p0.R, p0.position), expected_mask(K, R, P)
    shift = centroid(want) - centroid(want0)                         # from the two projectors only
    assert np.linalg.norm(shift) > 10.0                              # the change is visible
    assert iou(got, want) > 0.97
    np.testing.assert_allclose(centroid(got) - centroid(sphere_nominal), shift, atol=0.5)


def test_display_yaml_without_projector_is_a_configuration_error(tmp_path):
    cal = nominal_display_calib()
    path = tmp_path / "display.yaml"
    write_display_calib(str(path), DisplayCalib(camera=cal.camera, eye=cal.eye))
    assert load_display_calib(str(path)).projector is None

    async def scenario():
        async with NodeHarness(RendererNode, params={"width": 64, "height": 48, "display_calib": str(path)}):
            pass

    with pytest.raises(ValueError, match=r"display.yaml: missing entries \['projector'\]"):
        asyncio.run(scenario())


def test_geometry_comes_from_display_yaml(tmp_path):
    cal = nominal_display_calib()
    cal.eye.V = np.array([0.45, 0.01, 0.02])
    cal.eye.ipd = 0.060
    cal.eye.provenance = Provenance("test eye", source="lab")
    path = tmp_path / "display.yaml"
    write_display_calib(str(path), cal)
    g = load_geometry(str(SCENES_DIR / "organ.yaml"), str(path), 256, 192)
    np.testing.assert_array_equal(g.eye, [0.45, 0.01, 0.02])
    assert g.ipd == 0.060 and not g.nominal and g.scene.name == "organ"
    assert (g.projector.width, g.projector.height) == (256, 192)
    assert g.mesh[0].shape == load_scene(SCENES_DIR / "organ.yaml").surface_mesh()[0].shape
    n = load_geometry()
    assert n.nominal and any("NOMINAL" in line for line in n.log) and n.scene.name == "cylinder"


def test_scaled_projector_keeps_every_ray():
    p = Projector.default()
    q = scaled_projector(p, 256, 192)
    X = np.array([[0.0, 0.05, -0.03], [0.0, -0.1, 0.08], [-0.02, 0.0, 0.0]])
    uv_full = pixels(p.K, p.R, p.position, X, full=(1024, 768))      # at W x H = 512 x 384
    uv_q = pixels(q.K, q.R, q.position, X, full=(256, 192))         # q at 256 x 192, mapped to 512 x 384
    np.testing.assert_allclose(uv_q, uv_full, atol=1e-9)
    with pytest.raises(ValueError, match="width/height"):
        scaled_projector(p, 0, 10)


def test_shader_applies_the_projector_distortion_like_opencv():
    import moderngl

    p = Projector.default(320, 240, pixel=0.0028)
    D = np.array([0.3, -0.1, 0.004, -0.003, 0.02])
    ctx = moderngl.create_standalone_context(backend="egl")
    try:
        v, f = load_scene(SPHERE).surface_mesh()
        eye = paper.EYE + np.array([0.0, 0.02, 0.01])
        A = v.astype(float)
        X = eye + (A - eye) * (-eye[0] / (A[:, 0] - eye[0]))[:, None]         # screen points (x = 0)
        rvec, _ = cv2.Rodrigues(p.R.T)
        tvec = -p.R.T @ p.position
        for dist in (D, np.zeros(5)):
            r = StereoRenderer(p, ctx=ctx, shading=False, distortion=dist)
            r.set_mesh(v, f)
            got = r.projector_pixels(eye)
            want = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, p.K, dist)[0].reshape(-1, 2)
            assert np.abs(got - want).max() < 0.02
            r.release()
        shift = (cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, p.K, D)[0]
                 - cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, p.K, None)[0])
        assert np.abs(shift).max() > 1.0                             # the distortion is not negligible
        with pytest.raises(ValueError, match="distortion"):
            StereoRenderer(p, ctx=ctx, distortion=[0.1, 0.2])
    finally:
        ctx.release()
