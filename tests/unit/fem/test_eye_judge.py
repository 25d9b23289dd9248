"""The FEM's judge (flexsheet/fem/eye_judge.py) against closed forms: shape against sliding, each eye's
outline, the dent's gap to the fingertip, and frame-to-frame jumps, in projector pixels."""

import types

import numpy as np
import pytest
import trimesh
from test_eye_view import _plane

from flexsheet.fem.eye_judge import contact_gap, contour_segments, frame_jumps, judge, silhouette_px
from flexsheet.fem.eye_view import IPD, eyes
from flexsheet.model import geometry

PX = geometry.PIXEL_ON_SCREEN
V = geometry.EYE


def _sphere(R: float = 0.035, sub: int = 4):
    s = trimesh.creation.icosphere(sub, radius=R)
    return s.vertices + [-R, 0.0, 0.0], np.asarray(s.faces), np.array([-R, 0.0, 0.0])


def _rot_z(p, c, ang):
    c_, s_ = np.cos(ang), np.sin(ang)
    R = np.array([[c_, -s_, 0.0], [s_, c_, 0.0], [0.0, 0.0, 1.0]])
    return (p - c) @ R.T + c


def test_a_rotated_sphere_only_slides_and_its_outline_stays():
    pts, faces, c = _sphere()
    ang = 0.05                                   # rad about z: the front point slides 1.75 mm along y
    rot = _rot_z(pts, c, ang)
    (o,), k = judge([rot], pts, faces)
    assert k > 0.3 * len(pts)
    # shape: the rotated vertices lie on the same sphere; the polygon's chords differ by < its sagitta
    assert o["shape_px"] < 0.05
    # sliding at the front point: R·θ = 1.77 mm at x = 0 (on the screen): 2.5 px; nearer the eye less moves
    assert o["sliding_px"] == pytest.approx(0.035 * ang / PX, rel=0.08)
    assert o["total_px"] >= o["sliding_px"] - o["shape_px"] - 1e-9   # the triangle inequality
    assert o["silhouette_px"] < 0.15


def test_a_normal_offset_is_shape_and_moves_the_outline():
    pts, faces, c = _sphere()
    grown = c + (pts - c) * (1.0 + 0.001 / 0.035)          # every point 1 mm out along its normal
    (o,), _ = judge([grown], pts, faces)
    assert o["sliding_px"] < 0.05
    # the outline: the tangent cone from the eye to a sphere of radius R seen on the screen has radius
    # R·D/√(L² − R²) (L the eye–centre distance, D the eye–screen distance); 1 mm on R changes it by
    # D·L²/(L² − R²)^{3/2} · 1 mm
    L, D, R = 0.4 + 0.035, 0.4, 0.035
    want = D * L ** 2 / (L ** 2 - R ** 2) ** 1.5 * 0.001 / PX
    # each eye sits 32 mm off the axis: its cone is nearly the same
    assert o["silhouette_px"] == pytest.approx(want, rel=0.05)
    # a vertex facing the eye moves along the line of sight: its shape error is the outline's at most
    assert 0.1 < o["shape_px"] <= want * 1.05


def test_the_interpolated_outline_is_the_tangent_cone():
    pts, faces, c = _sphere()
    e = V
    seg = contour_segments(pts, faces, e).reshape(-1, 3)
    assert len(seg) > 100
    # on the sphere (within the chord's sagitta) and tangent to the ray: (T − C)·(T − E) = 0
    assert np.abs(np.linalg.norm(seg - c, axis=1) - 0.035).max() < 3e-4
    cosang = (np.einsum("ij,ij->i", seg - c, seg - e)
              / (np.linalg.norm(seg - c, axis=1) * np.linalg.norm(seg - e, axis=1)))
    assert np.abs(cosang).max() < 0.02


def test_a_finger_hiding_the_outline_hides_its_error():
    pts, faces, c = _sphere()
    moved = pts.copy()
    top = pts[:, 2] > 0.030                                   # a bump on the top of the outline
    moved[top] += [0.0, 0.0, 0.002]
    assert silhouette_px(moved, pts, faces) > 1.0
    cover = types.SimpleNamespace(center=np.array([0.045, 0.0, 0.045]), direction=np.array([0.0, 0.0, -1.0]),
                                  radius=0.04)                # a big occluder between the eyes and the top
    assert silhouette_px(moved, pts, faces, cover) < silhouette_px(moved, pts, faces)


def test_contact_gap_and_penetration_in_disparity():
    pts, faces = _plane()
    r = 0.008
    for g in (0.002, -0.001):
        fg = types.SimpleNamespace(center=np.array([r + g, 0.0, 0.0]), radius=r)
        out = contact_gap(pts, faces, fg)
        assert out["gap_m"] == pytest.approx(g, abs=1e-9)
        # along the cyclopean line of sight: each eye sees the gap shifted by e_y·g/(V_x − g) on the screen,
        # and the pair's disparity changes by IPD·|g|/(V_x − g)
        assert out["gap_px"] == pytest.approx(IPD * abs(g) / (0.4 - g) / PX, rel=1e-6)
    fg = types.SimpleNamespace(center=np.zeros(3), radius=r)
    with pytest.raises(ValueError, match="finger.center"):
        contact_gap(pts, faces, fg)


def test_a_jump_between_frames_is_seen_and_a_smooth_motion_is_not():
    pts, faces = _plane(21)
    step = 0.0004                                             # 0.4 mm a frame along y, in the screen plane
    frames = [pts + [0.0, k * step, 0.0] for k in range(12)]
    assert frame_jumps(frames, faces).max() < 1e-9
    # accelerating: a second difference of a parabola's steps, 1/2·a·(2k)... stays at a·dt² / 2 px-scale
    acc = [pts + [0.0, 1e-5 * k * k, 0.0] for k in range(12)]
    assert frame_jumps(acc, faces).max() == pytest.approx(0.0, abs=1e-9)
    jumped = [f + ([0.0, 0.0, 0.0007] if k >= 6 else [0.0, 0.0, 0.0]) for k, f in enumerate(frames)]
    j = frame_jumps(jumped, faces)
    assert j.argmax() == 4                                    # the change 5 → 6 (jumps start at change 1 → 2)
    assert j.max() == pytest.approx(1.0, rel=1e-6)            # 0.7 mm on the screen plane: 1 px
    assert np.delete(j, [3, 4, 5]).max() < 1e-9  # the neighbours see half of it, the rest nothing


def test_bad_input_names_the_field():
    pts, faces = _plane(5)
    with pytest.raises(ValueError, match=r"models\[0\]"):
        judge([pts[:-1]], pts, faces)
    with pytest.raises(ValueError, match="finite"):
        judge([pts * np.nan], pts, faces)
    with pytest.raises(ValueError, match="at least 4"):
        frame_jumps([pts] * 3, faces)
    with pytest.raises(ValueError, match="fingers"):
        frame_jumps([pts] * 5, faces, fingers=[None])
    assert len(eyes()) == 2
