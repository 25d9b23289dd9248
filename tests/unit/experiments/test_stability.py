"""Where the methods fail (flexsheet.experiments.stability): the breaking point is where the error curve
crosses the limit (a refused value breaks at the latest), the calibration error is the stated size, the quick
run writes the chart and its JSON, and the graph sweep sets one error at a time."""

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


def test_graph_stability_sets_one_error_at_a_time_and_finds_where_it_breaks(tmp_path):
    """flexsheet experiment stability --graph: each error reaches the graph as one launch override (camera
    noise, the camera link's delay in s, lost frames); the breaking points come from the felt rows; the chart
    says them."""
    import json

    from flexsheet.experiments.stability import GRAPH_SWEEPS, breaking_point, graph_chart, graph_sets

    assert graph_sets("noise_scale", 8.0, tmp_path, 0) == ["camera.noise_scale=8"]
    assert graph_sets("link_delay_ms", 50.0, tmp_path, 0) == ["camera.link_delay_s=0.05"]
    assert graph_sets("drop_rate", 0.6, tmp_path, 0) == ["camera.drop_rate=0.6"]
    assert graph_sets("base_error", 0.0, tmp_path, 0) == []                 # the twin's own registration
    with pytest.raises(ValueError, match="unknown error 'x'"):
        graph_sets("x", 1.0, tmp_path, 0)
    # baselines first
    assert all(v[1][0] == (1.0 if k == "noise_scale" else 0.0) for k, v in GRAPH_SWEEPS.items())
    x, y = [0.0, 25.0, 50.0, 100.0], [0.11, 0.15, 0.30, 0.50]
    assert breaking_point(x, y, 0.359) == pytest.approx(50.0 + 50.0 * (0.359 - 0.30) / 0.20)
    assert breaking_point(x, y, 0.9) is None
    res = {"title": "t", "paper_dtheta_deg": 0.359, "target_dtheta_deg": 0.18, "errors": {
        "link_delay_ms": {"label": "ms",
                          "rows": [{"value": a, "dtheta_mean_deg": b} for a, b in zip(x, y, strict=True)],
                          "breaks_paper_at": breaking_point(x, y, 0.359),
                          "breaks_target_at": breaking_point(x, y, 0.18)}}}
    graph_chart(res, tmp_path / "s.png")
    assert (tmp_path / "s.png").stat().st_size > 5000 and json.dumps(res)


def test_a_refused_value_is_where_the_error_breaks_at_the_latest():
    from flexsheet.experiments.stability import breaking_point

    assert breaking_point([0.0, 4.0, 8.0, 16.0], [0.11, 0.15, 0.28, float("inf")], 0.359) == 16.0
    assert breaking_point([0.0, 4.0, 8.0, 16.0], [0.11, 0.40, 0.28, float("nan")], 0.359) == pytest.approx(
        0.0 + 4.0 * (0.359 - 0.11) / (0.40 - 0.11))


def test_breaking_point():
    assert breaking_point([0, 1, 2, 4], [0.1, 0.3, 0.9, 2.0], 0.7) == pytest.approx(1 + 0.4 / 0.6)
    assert breaking_point([0, 1], [0.1, 0.2], 0.7) is None
    assert breaking_point([1, 2], [0.9, 1.0], 0.7) == 1.0
