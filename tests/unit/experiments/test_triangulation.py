"""``flexsheet experiment triangulation --quick`` end to end (one truth seed, fewer points): the numbers it
writes are those of the real XIMEA pairs and of the honest twin, judged against the fingertip target (0.5 mm
RMS)."""

from __future__ import annotations

import json
import math

import pytest

from flexsheet.experiments.triangulation import TARGET_MM, main

pytestmark = pytest.mark.slow


def test_quick_run_writes_the_measured_accuracy_and_where_it_breaks(tmp_path):
    assert main(["--out", str(tmp_path), "--quick"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    for png in ("accuracy_speed.png", "stability.png", "honest.png", "sensor_noise.png"):
        assert (tmp_path / png).stat().st_size > 10_000, png
    # the real 17 pairs, cross-validated: sub-pixel epipolar error, the 24 mm square within 2 %
    v = s["stereo_validation"]
    assert v["pairs"] == 17 and 0.05 < v["epipolar_rms_px"] < 0.5
    assert v["square_mean_m"] == pytest.approx(0.024, rel=0.02)
    # the honest twin (registered camera, rendered views): within the target, the quiet camera better still
    real, ideal = s["honest_static_rms_mm"][0], s["honest_static_rms_mm_ideal"][0]
    assert 0.05 < ideal < real < TARGET_MM and s["honest_static_target_met"] is True
    assert 0.05 < s["twin_end_to_end_rms_mm"] < TARGET_MM
    # stability: 16x the camera's noise breaks it; an unregistered camera is centimetres off at once
    st = s["honest_stability"]
    assert st["noise_scale"]["breaking"]["first_failing"] in (4.0, 16.0)
    assert st["calibration_scale_unregistered"]["rms_mm"][0] > 5.0
    assert all(math.isfinite(x) and x < TARGET_MM for x in st["calibration_scale"]["rms_mm"])
