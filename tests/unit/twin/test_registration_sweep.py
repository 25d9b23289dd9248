"""``flexsheet calibrate display --sweep --quick`` (:func:`flexsheet.twin.registration_sweep.run_sweep`) on
one drawn truth seed: each estimate's error falls with the number of poses and ends within its target, and the
failure modes say why (a dark sheet, a bowed board)."""

from __future__ import annotations

import json

import pytest

from flexsheet.twin.registration_sweep import run_sweep

pytestmark = pytest.mark.slow


def _last(series: dict) -> dict:
    return series[max(series, key=int)]


def test_quick_sweep_ends_within_every_target(tmp_path, caplog):
    caplog.set_level("INFO", logger="flexsheet.twin.registration_sweep")
    doc = run_sweep([3], str(tmp_path), quick=True)
    assert json.loads((tmp_path / "sweep.json").read_text())["seeds"] == [3]
    assert (tmp_path / "calibration_sweep.png").stat().st_size > 10_000
    t, res = doc["targets"], doc["per_seed"][3]
    cam = res["camera"]
    assert (_last(cam)["translation_error_mm"] < t["camera_mm"]
            and _last(cam)["rotation_error_deg"] < t["camera_deg"])
    # more views help
    assert cam[min(cam, key=int)]["translation_error_mm"] > _last(cam)["translation_error_mm"]
    pj = _last(res["projector"])
    assert pj["translation_error_mm"] < t["projector_mm"] and pj["reprojection_px"] < t["projector_px"]
    for side in ("left", "right"):
        assert _last(res["arms"][side])["translation_error_mm"] < t["arms_mm"], side
    fm = doc["failure_modes"]
    assert any("error" in v for v in fm["dark_sheet"].values()), fm["dark_sheet"]  # too dark: refused, named
    said = [r.getMessage() for r in caplog.records if r.name == "flexsheet.twin.registration_sweep"]
    assert said[0] == "sweep seed 3: 12 board views" and said[-1].startswith("wrote ")
