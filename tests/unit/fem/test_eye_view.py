"""The FEM's accuracy metric as the eyes see it (flexsheet/fem/eye_view.py): which vertices each eye sees past
the finger and the surface itself, and errors in projector pixels on the imaginary screen."""

import types

import numpy as np
import pytest

from flexsheet.fem.eye_judge import judge
from flexsheet.fem.eye_view import FINGER_LENGTH, eyes, finger_capsule, screen_px, seen
from flexsheet.model import geometry

V = geometry.EYE


def visible_px_error(model, ref, faces, eye_pair=None):
    """The vertex-to-vertex figure (``total_px``) of :func:`flexsheet.fem.eye_judge.judge` and the seen
    count."""
    out, k = judge([model], ref, faces, eye_pair=eye_pair, silhouette=False)
    return out[0]["total_px"], k


def _plane(n: int = 41, half: float = 0.05, x: float = 0.0):
    """A square grid of the plane x = ``x`` facing the eye: (n², 3) points and its triangles."""
    g = np.linspace(-half, half, n)
    y, z = np.meshgrid(g, g)
    pts = np.c_[np.full(y.size, x), y.ravel(), z.ravel()]
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            faces += [[a, a + 1, a + n], [a + 1, a + n + 1, a + n]]
    return pts, np.array(faces)


def _finger(tip_x: float = 0.0, r: float = 0.008):
    """A finger touching the plane x = tip_x at the origin, pushing along −x (its body toward the user)."""
    return types.SimpleNamespace(center=np.array([tip_x + r, 0.0, 0.0]), direction=np.array([-1.0, 0.0, 0.0]),
                                 radius=r)


def test_the_finger_hides_its_shadow_and_nothing_else():
    pts, faces = _plane()
    fg = _finger()
    a, b, r = finger_capsule(fg)
    assert np.allclose(b - a, [FINGER_LENGTH, 0.0, 0.0]) and r == 0.008
    vis = seen(pts, faces, V, (a, b, r))
    lat = np.hypot(pts[:, 1], pts[:, 2])
    # the capsule's far end (x = 88 mm) casts the widest
    # shadow: r * 0.4 / (0.4 - 0.088) = 10.3 mm on the plane
    assert not vis[lat < 0.0079].any()
    assert vis[lat > 0.0106].all()
    assert 0 < (~vis).sum() < 0.05 * len(pts)
    # without the finger the flat surface hides nothing from the eye in front of it
    assert seen(pts, faces, V).all()


def test_a_closed_surface_hides_its_far_side():
    import trimesh

    s = trimesh.creation.icosphere(4, radius=0.035)
    pts = s.vertices + [-0.035, 0.0, 0.0]
    vis = seen(pts, s.faces, V)
    assert vis[pts[:, 0] > -0.02].all()          # the near cap
    assert not vis[pts[:, 0] < -0.040].any()     # the far side, behind the centre
    assert 0.40 < vis.mean() < 0.50              # an eye 0.4 m away sees less than half a 35 mm sphere


def test_pixels_on_the_imaginary_screen():
    pts, faces = _plane(11)
    shifted = pts + [0.0, geometry.PIXEL_ON_SCREEN, 0.0]
    err, k = visible_px_error(shifted, pts, faces)
    assert err == pytest.approx(1.0, abs=1e-9) and k == len(pts)
    # a move along one eye's line of sight is invisible to that eye, and seen by the other (parallax)
    left, right = eyes()
    d = pts - left
    along = pts + 0.005 * d / np.linalg.norm(d, axis=1)[:, None]
    assert visible_px_error(along, pts, faces, eye_pair=left[None])[0] < 1e-9
    assert visible_px_error(along, pts, faces, eye_pair=right[None])[0] > 0.3
    # behind the screen the same lateral move looks smaller, by V_x / (V_x - x)
    p = np.array([[-0.1, 0.0, 0.0], [-0.1, 0.001, 0.0]])
    s = screen_px(p, V)
    assert (s[1, 0] - s[0, 0]) * geometry.PIXEL_ON_SCREEN == pytest.approx(0.001 * 0.4 / 0.5)


def test_bad_input_names_what_is_wrong():
    pts, faces = _plane(5)
    with pytest.raises(ValueError, match="must match"):
        visible_px_error(pts[:-1], pts, faces)
    with pytest.raises(ValueError, match="faces index vertices 0..24"):
        seen(pts, faces + 1, V)
    with pytest.raises(ValueError, match=r"\(k, 3\)"):
        seen(pts[:, :2], faces, V)
    with pytest.raises(ValueError, match="plane through the eye"):
        screen_px(np.array([[0.4, 0.1, 0.0]]), V)
