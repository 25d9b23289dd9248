"""Where the methods fail (flexsheet.experiments.stability): the breaking point is where the error curve crosses
the limit, the calibration error is the stated size, and the quick run writes the chart and its JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexsheet.experiments.stability import breaking_point, main, perturb_bases
from flexsheet.twin.truth import TwinTruth


def test_breaking_point_interpolates_the_crossing():
    assert breaking_point([0, 1, 2], [0.1, 0.2, 0.4], 0.3) == pytest.approx(1.5)
    assert breaking_point([0, 1, 2], [0.5, 0.6, 0.7], 0.3) == 0.0          # already broken
    assert breaking_point([0, 1, 2], [0.1, 0.2, 0.25], 0.3) is None       # never within the sweep


def test_perturbed_bases_move_by_the_stated_size():
    bases = TwinTruth.draw(0, "realistic").bases
    assert all(np.array_equal(perturb_bases(bases, 0.0, 1)[s], bases[s]) for s in bases)
    d_t, d_r = [], []
    for seed in range(40):
        p = perturb_bases(bases, 2.0, seed)
        for s in ("left", "right"):
            d_t.append(np.linalg.norm(p[s][:3, 3] - bases[s][:3, 3]))
            c = (np.trace(p[s][:3, :3].T @ bases[s][:3, :3]) - 1) / 2
            d_r.append(math.degrees(math.acos(min(1.0, c))))
    # scale 2: σ = 2 mm and 0.2° per axis → rms over 3 axes 2√3 mm and 0.2√3°
    assert np.sqrt(np.mean(np.square(d_t))) == pytest.approx(2e-3 * math.sqrt(3), rel=0.2)
    assert np.sqrt(np.mean(np.square(d_r))) == pytest.approx(0.2 * math.sqrt(3), rel=0.2)
    assert perturb_bases(bases, 1.0, 3)["left"] == pytest.approx(perturb_bases(bases, 1.0, 3)["left"])


def test_quick_run_writes_chart_and_breaking_points(tmp_path):
    assert main(["--quick", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "stability.json").read_text())
    assert (tmp_path / "stability.png").stat().st_size > 10_000
    b = doc["baselines"]["realistic_camera"]
    for kind in ("calibration_scale", "dropout", "marker_px"):
        rows = b[kind]["rows"]
        assert len(rows) == 2 and all(np.isfinite(r["dtheta_mean_deg"]) for r in rows)
        assert rows[-1]["dtheta_mean_deg"] > rows[0]["dtheta_mean_deg"]   # a larger error never helps
        assert "breaks_paper_at" in b[kind] and "breaks_target_at" in b[kind]
    assert doc["paper_dtheta_deg"] == pytest.approx(0.359)
    t = doc["tension_ratio"]
    assert len(t["rows"]) == 2 and all(r["10mm_max_mm"] > 0 for r in t["rows"])
