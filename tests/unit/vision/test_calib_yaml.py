"""The stereo calibration's YAML file (flexsheet.vision.calib_yaml): a round trip of a real calibration and
its message, a missing file named."""

import numpy as np
import pytest
from test_stereo_calibration import _pairs

from flexsheet.vision.calib_yaml import load_yaml, write_yaml
from flexsheet.vision.stereo_calibration import (
    calibrate_stereo,
    parse_board,
    to_message,
)


@pytest.fixture(scope="module")
def real_result():
    left, right, names = _pairs()
    assert len(left) == 17
    return calibrate_stereo(left, right, parse_board("chessboard:9x6", 0.024), names)


def test_yaml_round_trip_and_message(tmp_path, real_result):
    path = str(tmp_path / "c.yaml")
    d = real_result.as_dict()
    d["T_display_camera"] = np.diag([1.0, -1.0, -1.0, 1.0])
    write_yaml(path, d)
    back = load_yaml(path)
    for k in ("K1", "D1", "K2", "D2", "R", "T", "E", "F", "R1", "R2", "P1", "P2", "Q", "T_display_camera"):
        assert np.allclose(back[k], np.asarray(d[k]).reshape(back[k].shape), rtol=1e-12, atol=1e-12), k
    assert back["image_size"] == (640, 512)
    assert back["rms_px"] == pytest.approx(real_result.rms_px)
    from messages import Header
    msg = to_message(back, Header(stamp=1.0, frame_id="camera_left"))
    assert tuple(msg.image_size) == (640, 512) and np.allclose(msg.T, real_result.T)


def test_load_yaml_missing_file(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        load_yaml(str(tmp_path / "none.yaml"))
