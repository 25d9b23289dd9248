"""The lab's captured-images path (flexsheet.calibration.sources): saved frames read back by ImageDirSource
give the same estimates as the frames the twin handed over."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.calibration.procedures import QUICK
from flexsheet.calibration.sources import ImageDirSource, save_frames
from flexsheet.display.calibrate import camera_pose_main, eye_main


def test_lab_images_path_runs_the_same_estimator(twin_and_camera, tmp_path):
    _, _, views, r = twin_and_camera
    save_frames(str(tmp_path / "frames"), board_views=views)
    src = ImageDirSource(str(tmp_path / "frames"))
    again = src.board_views(QUICK.board_spec())
    assert len(again) == len(views) and np.array_equal(again[3][1], views[3][1])
    out = tmp_path / "lab"
    assert camera_pose_main(["--images", str(tmp_path / "frames"), "--out", str(out)]) == 0
    d = load_display_calib(str(out / "display.yaml"), require=("camera",))
    assert np.allclose(d.camera.T_display_camera, r.T_display_camera, atol=1e-9)
    assert d.camera.provenance.source.startswith("lab images")
    assert eye_main(["--V", "0.41,0,0.01", "--ipd", "0.062", "--out", str(out)]) == 0
    d = load_display_calib(str(out / "display.yaml"), require=("camera", "eye"))
    assert np.allclose(d.eye.V, [0.41, 0, 0.01]) and d.eye.ipd == 0.062
    with pytest.raises(ValueError, match="lacks arms.left.joints"):
        ImageDirSource(str(tmp_path / "frames")).marker_frames("left")


def test_lab_images_path_for_the_arms(twin_and_camera, tmp_path):
    from flexsheet.calibration.display_calib import CameraEntry, DisplayCalib, Provenance
    from flexsheet.calibration.procedures import run_arms
    from flexsheet.twin.registration import TwinSource

    truth, twin, _, r = twin_and_camera
    calib = DisplayCalib(camera=CameraEntry(r.T_display_camera, Provenance("test"), r.stereo))
    opts = QUICK.__class__(arm_configs=8)
    src = TwinSource(twin, marker_frames=2)
    nom = nominal_display_calib().arms["left"]
    qs = arms_mod.plan_arm_configs("left", 8, nom.T_display_base, nom.marker_offset, r.stereo,
                                   r.T_display_camera)
    frames, q = src.marker_frames("left", qs)
    save_frames(str(tmp_path), arms={"left": (frames, q)})
    lab = run_arms(ImageDirSource(str(tmp_path)), opts, calib, ("left",))["left"]
    again = run_arms(_Replay(frames, q), opts, calib, ("left",))["left"]
    # same frames, same estimator: the same base, whichever source hands them over
    assert np.allclose(lab[0].T_display_base, again[0].T_display_base, atol=1e-12)
    assert truth.base_error("left", lab[0].T_display_base)[0] < 2e-3
    assert lab[0].provenance.source.startswith("lab images") and lab[1].n_configs == 8


class _Replay:
    """A frame source that hands back given marker frames (the twin's, captured once)."""

    label = "replay"

    def __init__(self, frames, q):
        self.frames, self.q = frames, q

    def marker_frames(self, side, joints):
        return self.frames, self.q
