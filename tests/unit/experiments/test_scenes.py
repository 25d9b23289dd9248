"""The scenes experiment (flexsheet.experiments.scenes): palpation in-process, the presented stiffness peaking
over the organ's tumour."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model.scenes import SCENES_DIR, load_scene


def test_planner_tension_follows_the_organ_tumour():
    """Palpation in-process: stroking the organ pressed 5 mm, the sheet presents its stiffness (scaled into
    the arms' range) — peaking over the tumour, and the tension above what the same place needs without it."""
    from flexsheet.experiments.scenes import (
        PALPATION_DEPTH,
        peak_along_path,
        run_series,
        stiffness_along_path,
    )

    sc = load_scene(SCENES_DIR / "organ.yaml")
    arc_inc = stiffness_along_path(sc, (0.5,), n=41)["inclusions"][0]["arc_mm"]
    series, _ = run_series(sc, "stroke", 0.36, depth=PALPATION_DEPTH)
    pk = peak_along_path(series, arc_inc)
    for key in ("presented_n_per_m", "contrast", "tension_over_no_tumour"):
        assert abs(pk[key]["arc_of_max_mm"] - arc_inc) < 6.0, (key, pk)
        assert pk[key]["max_over_far_median"] > 1.05, (key, pk)
    assert np.mean(series["at_limit"]) < 0.05                          # inside the arms' range


@pytest.mark.slow
def test_quick_run_on_the_organ_writes_table1_and_the_tumour_where_it_is(tmp_path):
    """``flexsheet experiment scenes --quick --scene organ``: one seed, the 10 s stroke; the stiffness the
    object asks peaks over the tumour at every depth and rises with depth; its contrast stays under the 15 % a
    finger notices (the medical use this scene stands for is not presentable yet)."""
    import json

    from flexsheet.experiments.scenes import main

    assert main(["--out", str(tmp_path), "--quick", "--scene", "organ"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    row = s["table1"]["organ"]["10"]
    assert row["n"] > 100 and row["seeds"] == 1 and row["ik_refused"] == 0.0
    assert 0.0 < row["dtheta_mean_deg"] < 2.0 and 0.0 < row["dd_mean_mm"] < 5.0
    org = s["organ"]
    tumour = org["inclusion"][0]["arc_mm"]
    peaks = org["peaks_along_path"]
    ks = [peaks[d]["k_max_n_per_m"] for d in ("0.5", "2", "5", "10")]
    assert ks == sorted(ks) and ks[0] > 0.0                               # deeper presses ask more
    for d, p in peaks.items():
        assert abs(p["arc_of_max_mm"] - tumour) <= 4.0, d                  # over the tumour (4 mm bins)
        assert 1.0 < p["contrast_max"] < 1.15, d
    assert (tmp_path / "compliance_organ.png").stat().st_size > 10_000
