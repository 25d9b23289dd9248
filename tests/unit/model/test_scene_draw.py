"""Scenes drawn at random (flexsheet/model/scene_draw.py): deterministic, valid, every kind, placed on the
home sheet, convex where they should be."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model.scene_draw import KINDS, draw_scene, random_rotation, rpy_from_rotation, write_scene
from flexsheet.model.scene_parts import rotation_rpy
from flexsheet.model.scenes import load_scene


def test_rpy_round_trips_through_the_scene_pose_convention():
    rng = np.random.default_rng(3)
    for _ in range(200):
        R = random_rotation(rng)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0.999
        assert np.allclose(rotation_rpy(rpy_from_rotation(R)), R, atol=1e-9)
    R = rotation_rpy((10.0, 90.0, 0.0))                    # gimbal lock: still the same rotation
    assert np.allclose(rotation_rpy(rpy_from_rotation(R)), R, atol=1e-9)


def test_a_seed_draws_the_same_scene_and_seeds_cover_every_kind():
    assert draw_scene(5)[0] == draw_scene(5)[0]
    assert draw_scene(5)[0] != draw_scene(6)[0]
    kinds = set()
    for s in range(40):
        sc = draw_scene(s)[0]
        kinds.add(sc["description"].split(": ")[1].split(",")[0])
    assert kinds == {"ellipsoid", "superquadric", "capsule", "cylinder"}    # dented ones are ellipsoids
    assert any("dented" in draw_scene(s)[0]["description"] for s in range(40))
    assert set(KINDS) == {"ellipsoid", "superquadric", "capsule", "cylinder", "dented"}
    with pytest.raises(ValueError, match="seed must be an int >= 0"):
        draw_scene(-1)


@pytest.mark.parametrize("seed", range(10))
def test_a_drawn_scene_loads_touches_the_home_sheet_and_its_stroke_faces_the_user(seed, tmp_path):
    sc = load_scene(write_scene(seed, tmp_path)).check_geometry()
    shape = sc.shape()
    # the body's front (its support along +x) lies on the home sheet, x = 0, within 0.1 mm
    front = shape.support((1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert abs(front[0]) < 1e-4
    pts, normals = sc.stroke_points(16)
    assert np.all(normals[:, 0] > 0.0)                      # the stroke stays on the user's side
    assert 0.005 < sc.stroke_length() < 0.1
    assert 3e3 <= sc.material.E <= 30e3 and 0.40 <= sc.material.nu <= 0.49
    if sc.object.kind == "mesh":
        assert sc.trimesh().is_watertight
        assert sc.trimesh().is_convex == ("dented" not in sc.description)
