"""``flexsheet calibrate display --draws N`` (:mod:`flexsheet.twin.registration_draws`): the truths are
drawn reproducibly, and each target's median, worst and missing seeds are counted from the per-seed summaries
(here summaries with known errors stand in for the registrations, which take ~10 s a seed; the registration
itself is tested in test_registration_sweep and the live test)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexsheet.twin import registration_draws as rd
from flexsheet.twin.registration import TARGETS


def test_drawn_seeds_are_reproducible_distinct_and_in_range():
    a, b = rd.draw_seeds(30, 7), rd.draw_seeds(30, 7)
    assert a == b and len(set(a)) == 30 and all(10 <= s < 100_000 for s in a)
    assert rd.draw_seeds(30, 8) != a
    with pytest.raises(ValueError, match="draws"):
        rd.draw_seeds(0, 1)


def test_each_target_counts_its_misses_worst_and_median(tmp_path, monkeypatch):
    rng = np.random.default_rng(11)
    proj = {s: float(rng.uniform(0.2, 1.9)) for s in (101, 202, 303, 404, 505)}
    proj[303] = 2.3                                                     # one draw over the 2 mm target

    def fake(seed, out_dir, opts, realism):
        arm = {"translation_error_mm": 0.4, "rotation_error_deg": 0.01}
        return {"camera": {"translation_error_mm": 0.1 * (seed % 7), "rotation_error_deg": 0.02},
                "projector": {"translation_error_mm": proj[seed], "rotation_error_deg": 0.05,
                              "reprojection_px": 0.3},
                "arms": {"left": arm, "right": arm}, "targets": dict(TARGETS)}

    monkeypatch.setattr(rd, "run_display_sim", fake)
    doc = rd.run_draws(list(proj), str(tmp_path), draw=3)
    assert json.loads((tmp_path / "draws.json").read_text())["seeds"] == list(proj)
    assert (tmp_path / "draws.png").stat().st_size > 5_000
    p = doc["figures"]["projector.translation_error_mm"]
    assert p["misses"] == [303] and p["worst"] == 2.3 and p["worst_seed"] == 303
    assert p["median"] == pytest.approx(float(np.median(list(proj.values()))))
    assert p["met_share"] == pytest.approx(0.8) and p["verdict"] == "MISSED on 1 of 5"
    cam = doc["figures"]["camera.translation_error_mm"]                 # 0.1·(seed mod 7) mm: 505 -> 0.1·1
    assert cam["misses"] == [s for s in proj if 0.1 * (s % 7) > TARGETS["camera_mm"]]
    assert doc["figures"]["arms.left.translation_error_mm"]["verdict"] == "met"
    with pytest.raises(ValueError, match="seed"):
        rd.run_draws([], str(tmp_path))
