"""display.yaml (flexsheet.calibration.display_calib_file): OpenCV FileStorage round trip, clear errors for
missing and malformed entries, a bad entry refused on write."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from flexsheet.calibration.display_calib import (
    ENTRIES,
    ArmEntry,
    DisplayCalib,
    HeadCameraEntry,
    Provenance,
    SheetEntry,
    nominal_display_calib,
)
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.model import geometry


def _measured() -> DisplayCalib:
    c = nominal_display_calib()
    c.camera.provenance = Provenance("camera-pose: test", "2025-01-02T03:04:05Z", "twin seed 7", 21,
                                     {"rms_px": 0.061, "residual_mm": 0.43})
    c.projector.D = np.array([0.0123, 0.0, 0.0, 0.0, 0.0])
    A = np.random.default_rng(0).normal(size=(30, 30))
    c.camera.cov = A @ A.T * 1e-6
    c.arms["left"] = ArmEntry(geometry.pose_matrix(-0.051, 0.552, -0.398, -1.57),
                              np.array([0.011, -0.001, 0.041]),
                              Provenance("arms: test", n_poses=16, residuals={"residual_mm": 0.2}))
    c.head_camera = HeadCameraEntry(np.array([[601.0, 0, 318.0], [0, 601.5, 257.0], [0, 0, 1]]),
                                    np.array([-0.08, 0.05, 0, 0, 0]), 640, 512,
                                    geometry.pose_matrix(0.002, 0.003, 0.199, 0.01),
                                    Provenance("head: test", n_poses=30))
    c.sheet = SheetEntry(0.0231, 2.71, 0.51, 289.0, 18500.0, 0.0204, 0.21, -0.47,
                         Provenance("sheet: test", n_poses=15,
                                                                                residuals={"median_pct":
                                                                                               4.6}))
    return c


def test_round_trip_through_opencv_filestorage(tmp_path):
    c = _measured()
    path = str(tmp_path / "display.yaml")
    write_display_calib(path, c)
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    assert fs.isOpened()
    assert int(fs.getNode("format_version").real()) == 1
    cam = fs.getNode("camera")
    np.testing.assert_allclose(cam.getNode("T_display_camera").mat(), c.camera.T_display_camera, atol=1e-15)
    np.testing.assert_allclose(cam.getNode("K1").mat(), c.camera.stereo["K1"], atol=1e-12)
    np.testing.assert_allclose(cam.getNode("T").mat().ravel(), c.camera.stereo["T"], atol=1e-15)
    assert cam.getNode("provenance").getNode("source").string() == "twin seed 7"
    assert cam.getNode("provenance").getNode("residuals").getNode("rms_px").real() == pytest.approx(0.061)
    pj = fs.getNode("projector")
    np.testing.assert_allclose(pj.getNode("K").mat(), c.projector.K, atol=1e-12)
    np.testing.assert_allclose(pj.getNode("D").mat().ravel(), c.projector.D, atol=1e-15)
    np.testing.assert_allclose(pj.getNode("T_display_projector").mat(), c.projector.T_display_projector,
                               atol=1e-15)
    assert int(pj.getNode("width").real()) == 1024
    left = fs.getNode("arms").getNode("left")
    np.testing.assert_allclose(left.getNode("T_display_base").mat(), c.arms["left"].T_display_base,
                               atol=1e-15)
    np.testing.assert_allclose(left.getNode("marker_offset").mat().ravel(), [0.011, -0.001, 0.041],
                               atol=1e-15)
    eye = fs.getNode("eye")
    assert eye.getNode("mode").string() == "fixed"
    np.testing.assert_allclose(eye.getNode("V").mat().ravel(), geometry.EYE)
    fs.release()
    # and our own loader gives the same values back
    d = load_display_calib(path, require=ENTRIES)
    np.testing.assert_allclose(d.arms["left"].T_display_base, c.arms["left"].T_display_base, atol=1e-15)
    np.testing.assert_allclose(d.projector.D, c.projector.D)
    assert d.camera.provenance.residuals == {"rms_px": 0.061, "residual_mm": 0.43}
    assert d.camera.provenance.n_poses == 21 and d.camera.stereo["image_size"] == (640, 512)
    np.testing.assert_allclose(d.camera.cov, c.camera.cov, rtol=1e-14)
    assert d.projector.projector().K[0, 0] == pytest.approx(c.projector.K[0, 0])
    np.testing.assert_allclose(d.head_camera.T_display_camera, c.head_camera.T_display_camera, atol=1e-15)
    np.testing.assert_allclose(d.head_camera.D, c.head_camera.D)
    assert (d.head_camera.width, d.head_camera.K[1, 1]) == (640, 601.5)
    m = d.sheet.material()
    assert (m.contact_width, m.contact_growth, m.own_stiffness, m.own_growth, m.stretching, m.strain_offset,
            m.position_u, m.position_v) == (0.0231, 2.71, 0.51, 289.0, 18500.0, 0.0204, 0.21, -0.47)
    assert d.sheet.provenance.residuals == {"median_pct": 4.6}


def test_missing_entry_is_named(tmp_path):
    c = DisplayCalib(camera=nominal_display_calib().camera)
    path = str(tmp_path / "display.yaml")
    write_display_calib(path, c)
    with pytest.raises(ValueError, match=r"display\.yaml: missing entries \['projector', 'arms.left'"):
        load_display_calib(path, require=("camera", "projector", "arms.left"))
    assert load_display_calib(path, require=("camera",)).missing() == ["projector", "arms.left", "arms.right",
                                                                       "eye",
                                                                       "head_camera", "sheet"]


def test_malformed_entries_name_the_key(tmp_path):
    path = tmp_path / "display.yaml"
    write_display_calib(str(path), nominal_display_calib())
    text = path.read_text()
    # break the rigid transform of the projector: scale a rotation entry
    bad = text.replace("T_display_projector: !!opencv-matrix\n      rows: 4\n      cols: 4\n      dt: d\n    "
                       "  data: [ 0.,",
                       "T_display_projector: !!opencv-matrix\n      rows: 4\n      cols: 4\n      dt: d\n    "
                       "  data: [ 0.5,")
    assert bad != text
    path.write_text(bad)
    with pytest.raises(ValueError, match=r"display\.yaml: projector\.T_display_projector rotation block is "
                                         r"not a proper rotation"):
        load_display_calib(str(path))
    path.write_text(text.replace("   ipd: ", "   ipd_m: "))
    with pytest.raises(ValueError, match=r"missing key eye\.ipd"):
        load_display_calib(str(path))
    path.write_text(text.replace("format_version: 1", "format_version: 9"))
    with pytest.raises(ValueError, match="format_version must be 1"):
        load_display_calib(str(path))
    path.write_text("camera: [1, 2")
    with pytest.raises(ValueError, match="not a display calibration YAML"):
        load_display_calib(str(path))
    with pytest.raises(ValueError, match="not found"):
        load_display_calib(str(tmp_path / "nope.yaml"))
    # a sheet entry with a negative stretching term, and one with a term missing
    write_display_calib(str(path), _measured())
    text = path.read_text()
    path.write_text(text.replace("stretching: 18500.", "stretching: -18500."))
    with pytest.raises(ValueError, match=r"display\.yaml: sheet: stretching must be finite and >= 0"):
        load_display_calib(str(path))
    path.write_text(text.replace("   contact_growth:", "   growth:"))
    with pytest.raises(ValueError, match=r"missing key sheet\.contact_growth"):
        load_display_calib(str(path))
    # a file written before the position terms: the band alone there; a bad one is named
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("position_")]
    assert len(lines) == len(text.splitlines()) - 2
    path.write_text("\n".join(lines) + "\n")
    m = load_display_calib(str(path)).sheet.material()
    assert (m.position_u, m.position_v, m.contact_width) == (0.0, 0.0, 0.0231)
    path.write_text(text.replace("position_v: -0.4", "position_v: -1.4"))
    with pytest.raises(ValueError, match=r"display\.yaml: sheet: position_v must be finite and within"):
        load_display_calib(str(path))


def test_write_refuses_a_bad_entry(tmp_path):
    c = nominal_display_calib()
    c.arms["left"].T_display_base = np.diag([1.0, 1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="arms.left.T_display_base"):
        write_display_calib(str(tmp_path / "d.yaml"), c)
