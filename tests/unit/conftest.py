"""Fixtures shared by several packages' tests. ``home_patterns``: the Gray-code frames of the projector twin
at the home sheet (truth seed 3), read by calibration/test_projector and twin/test_registration_camera.
``model``, built once per worker: the real-time model of the sphere scene with a 4° stroke and a sticking
finger, that path tables are attached to (fem/test_path_snapshots, fem/test_scene_model,
fem/reference/test_path_table: one xdist group, ``SAME_WORKER`` in tests/conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.calibration import projector as pj
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.scene_model import SceneModel
from flexsheet.model.scenes import SCENES_DIR, load_scene, parse_scene
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import TwinTruth


def _scene():
    """The sphere with a short polyline stroke over its crown (2.5 mm, as a 4° arc) and a sticking finger: no
    sphere table applies (its stroke is no arc about the centre), so a path table does."""
    sc = load_scene(SCENES_DIR / "sphere.yaml")
    data = sc.model_dump()
    data["stroke"] = {"kind": "polyline", "points": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.00247]]}
    data["finger"] = {"radius": sc.finger.radius, "contact": "sticking"}
    return parse_scene(data, "<sphere, short stroke, sticking>")


@pytest.fixture(scope="package")
def model(tmp_path_factory):
    return SceneModel(_scene(), MeshSpec(0.015, 0.006, 0.012), order=1,
                      cache_dir=str(tmp_path_factory.mktemp("pathcache")))


@pytest.fixture(scope="module")
def home_patterns():
    truth = TwinTruth.draw(3)
    twin = CalibrationTwin(truth, seed=1)
    W, H = truth.projector_size
    pats = pj.gray_code_patterns(W, H)
    return truth, twin, pats, twin.pattern_frames(pats, np.eye(4), home_exact=True, frames=1)
