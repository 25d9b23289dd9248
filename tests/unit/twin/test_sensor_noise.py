"""The XIMEA sensor noise measured on real pairs (flexsheet.twin.sensor_noise): the model behind the twin's
image noise."""

from __future__ import annotations

import shutil
from pathlib import Path

from flexsheet.twin.sensor_noise import measure_ximea_noise

ROOT = Path(__file__).resolve().parents[3]


def test_measured_noise_model_on_real_pairs(tmp_path):
    src = ROOT / "tests" / "data" / "stereo_xi"
    for n in ("left01.jpg", "left05.jpg", "right01.jpg", "right05.jpg"):
        shutil.copy(src / n, tmp_path / n)
    r = measure_ximea_noise(str(tmp_path))
    m = r["model"]
    # four images against the 34-image medians behind XIMEA_NOISE: same camera, same order of magnitude
    assert 0.2 <= m["blur_px"] <= 1.0
    assert 2.0 < r["median"]["sigma_black_dn"] < 7.0 and 4.0 < r["median"]["sigma_white_dn"] < 12.0
    assert r["median"]["sigma_white_dn"] > r["median"]["sigma_black_dn"]          # shot noise
    assert 20 < m["black_dn"] < 60 and 110 < m["white_dn"] < 230
    assert 0.08 < m["corner_rms_px"] < 0.25
