"""The FEM's accuracy on any scene as the eyes see it (flexsheet/experiments/fem_scene.py): the organ judged
over its declared depths, the reference's band, the moving finger, and the judged range."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.model.scenes import SCENES_DIR


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_organ_is_judged_as_the_eyes_see_it_over_its_declared_depths(tmp_path):
    """flexsheet experiment fem --quick --scene: the model the node serves (the organ's path table) against
    the scene's reference on two coarse levels, over the scene's declared 0-15 mm, in projector pixels of what
    either eye sees; the table beats linear P2 on the reference's own mesh, and the chart says its
    verdicts."""
    import json

    from flexsheet.experiments.fem_scene import run_scene

    s = run_scene(SCENES_DIR / "organ.yaml", str(tmp_path / "out"), True, str(tmp_path / "cache"), jobs=1,
                  levels=(0.012, 0.009, 0.00675))
    v, r = s["visible"], s["reference"]
    assert s["scene"]["max_depth_mm"] == pytest.approx(15.0) and v["range_mm"] == [0.0, pytest.approx(15.0)]
    assert v["depths_mm"] == pytest.approx([5.0, 10.0, 15.0]) and s["scene"]["contact"] == "sticking"
    assert "path table" in s["realtime"]["method"] and 0 < s["realtime"]["update_ms"] < 20
    assert (all(math.isfinite(x) and x > 0 for x in v["px_by_depth"])
            and v["shape_px_max"] == max(v["px_by_depth"]))
    assert v["px_by_depth"][-1] < v["linear_fine_px"]          # the nonlinear table beats the linear law
    assert all(80 < k < 2000 for k in v["seen_vertices_by_depth"]), v["seen_vertices_by_depth"]
    # shape and sliding together bound the vertex-to-vertex figure (the triangle inequality on the screen)
    for sh, sl, tot in zip(v["shape_px_by_depth"], v["sliding_px_by_depth"], v["total_px_by_depth"],
                           strict=True):
        assert tot <= sh + sl + 1e-9
    assert [lv["h_fine_m"] for lv in r["levels"]] == [0.012, 0.009, 0.00675]
    assert all(lv["newton_converged"] for lv in r["levels"])
    assert r["band_kind"] == "gci" and r["ratios"] == pytest.approx([4 / 3, 4 / 3])
    g = r["gci_px"]
    assert g == "inf" or (math.isfinite(g) and r["converged"] == (g <= 0.5))
    # the moving finger: every frame of the push (0.25 mm) and of the stroke (0.5 mm) judged
    c, t = s["contact"], s["temporal"]
    assert c["push"]["frames"] == 60 and c["stroke"]["frames"] > 100 and c["push"]["methods"] == [
        "path_snapshots"]
    assert 0 <= c["gap_px_max"] < 20 and -8.0 < c["push"]["gap_mm_range"][0] <= c["push"]["gap_mm_range"][
        1] < 8.0
    assert len(t["push"]["jump_px"]) == 57 and 0 <= t["jump_px_p99"] <= t["jump_px_max"]
    chart = json.loads((tmp_path / "out" / "accuracy_organ.json").read_text())
    assert chart["verdict"]["served"] == ("met" if v["shape_px_max"] <= 1.0 else "MISSED")
    assert (tmp_path / "out" / "accuracy_organ.png").stat().st_size > 5000


def test_the_judged_range_ends_where_the_reference_stops_converging_but_not_below_15_mm():
    """visible.converged_to_mm: the deepest depth up to which the reference's band is 0.5 px at every depth
    (the rounded box's 4/3 mm levels: 25 mm); none below the 15 mm floor (the organ's: 10 mm)."""
    from flexsheet.experiments.fem_scene import judged_range

    d = np.arange(1, 7) * 0.005
    assert judged_range(d, np.array([0.12, 0.25, 0.44, 0.45, 0.46, 0.59])) == pytest.approx(0.025)
    assert judged_range(d, np.full(6, 0.3)) == pytest.approx(0.030)
    assert judged_range(d[:3], np.array([0.13, 0.44, 0.87])) is None
    assert judged_range(d, np.array([0.6, 0.1, 0.1, 0.1, 0.1, 0.1])) is None     # not converged at 5 mm
    assert judged_range(d, None) is None
