"""The head camera's registration on the chin-rest fixture and the eye's offset in the glasses, in the
twin."""

import math

import cv2
import numpy as np
import pytest

from flexsheet.calibration.head_camera import (
    design_head_camera,
    eye_entry,
    fixture_poses,
    register_head_camera,
)
from flexsheet.twin.head_rig import HeadRigTwin, true_head_camera
from flexsheet.vision.glasses import GlassesTracker


@pytest.mark.parametrize("seed", [4, 11])
def test_registration_finds_the_true_camera_and_the_eye(seed):
    rig = HeadRigTwin(seed)
    K0, _, w, h = design_head_camera()
    poses = fixture_poses()
    finder = GlassesTracker(K0, None, np.eye(4), rig.board, np.zeros(3), 0.064)
    entry = register_head_camera([finder.detect(im) for im in rig.fixture_images(poses)], poses, rig.board,
                                 K0,
                                 (w, h), "twin")
    K, _, T, _, _ = true_head_camera(seed)
    assert np.linalg.norm(entry.T_display_camera[:3, 3] - T[:3, 3]) < 0.006  # mount drawn ~5 mm per axis off
    dR = cv2.Rodrigues(entry.T_display_camera[:3, :3].T @ T[:3, :3])[0]
    assert math.degrees(np.linalg.norm(dR)) < 0.8                                  # drawn ~1 deg off
    assert entry.provenance.residuals["rms_px"] < 1.5 and entry.provenance.n_poses >= 25
    tracker = GlassesTracker(entry.K, entry.D, entry.T_display_camera, rig.board, np.zeros(3), 0.064)
    one = eye_entry([tracker.track(rig.chin_rest_image()).T_display_glasses], rig.pupillometer_ipd())
    eye = eye_entry([tracker.track(rig.chin_rest_image()).T_display_glasses for _ in range(5)],
                    rig.pupillometer_ipd(), source="twin")
    assert eye.mode == "tracked" and eye.provenance.n_poses == 5 and one.provenance.n_poses == 1
    assert np.linalg.norm(one.glasses_eye_offset - rig.viewer.eye_offset) < 0.006  # chin rest: ~1 mm per axis
    assert np.linalg.norm(eye.glasses_eye_offset - rig.viewer.eye_offset) < 0.003    # five sittings: ~0.45 mm
    assert 0.0 < eye.provenance.residuals["offset_spread_mm"] < 3.0
    assert abs(eye.ipd - rig.viewer.ipd) < 0.002


def test_too_few_views_are_refused():
    rig = HeadRigTwin(0, "ideal")
    K0, _, w, h = design_head_camera()
    poses = fixture_poses()[:3]
    finder = GlassesTracker(K0, None, np.eye(4), rig.board, np.zeros(3), 0.064)
    with pytest.raises(ValueError, match="fixture steps"):
        register_head_camera([finder.detect(im) for im in rig.fixture_images(poses)], poses, rig.board, K0,
                             (w, h))
    with pytest.raises(ValueError, match="one detection per"):
        register_head_camera([], poses, rig.board, K0, (w, h))


def test_the_lab_images_give_the_twins_registration(tmp_path):
    """Offline: the twin's head-camera images saved in the lab layout and read back register the same
    camera."""
    from flexsheet.calibration.procedures import run_head_camera
    from flexsheet.calibration.sources import ImageDirSource, save_frames
    from flexsheet.twin.registration import TwinSource

    class _Truth:
        seed, realism = 6, "realistic"

    class _Twin:
        truth = _Truth()

    twin = TwinSource(_Twin())
    poses = fixture_poses()
    save_frames(str(tmp_path), head=(twin.head_fixture_images(poses), twin.head_chin_rest_images(),
                                     twin.pupillometer_ipd()))
    lab = ImageDirSource(str(tmp_path))
    assert lab.has_head_camera
    a, ea = run_head_camera(TwinSource(_Twin()))
    b, eb = run_head_camera(lab)
    assert np.allclose(a.T_display_camera, b.T_display_camera, atol=1e-9)        # PNG is lossless
    assert np.allclose(ea.glasses_eye_offset, eb.glasses_eye_offset, atol=1e-9) and ea.ipd == eb.ipd
    (tmp_path / "manifest.json").write_text("{}")
    with pytest.raises(ValueError, match="head.ipd"):
        ImageDirSource(str(tmp_path)).pupillometer_ipd()
