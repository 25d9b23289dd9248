"""The scenes experiment (flexsheet.experiments.scenes): palpation in-process, the presented stiffness peaking
over the organ's tumour."""

from __future__ import annotations

import numpy as np

from flexsheet.model.scenes import SCENES_DIR, load_scene


def test_planner_tension_follows_the_organ_tumour():
    """Palpation in-process: stroking the organ pressed 5 mm, the sheet presents its stiffness (scaled into the
    arms' range) — peaking over the tumour, and the tension above what the same place needs without it."""
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
