"""``flexsheet experiment compliance`` (flexsheet.experiments.compliance): the presentable range and the mapping
that keeps ratios."""

from __future__ import annotations

import numpy as np
import pytest


def test_the_presentable_range_comes_from_the_first_limit_and_the_mapping_keeps_ratios(tmp_path):
    """flexsheet experiment compliance: the range ends at the stretch where the clamp pulls the arm's 9.81 N (the
    strain limit, 30 %, comes later); one scale maps the scene's largest request to the range's top, so the ratio
    of two requests inside the range is the ratio presented; a request below the floor is presented at the floor
    (no contrast); the tumour's contrast is judged against the 23 % Weber fraction."""
    from flexsheet.experiments.compliance import presentable_range, run
    from flexsheet.model.tension import SheetMaterial, clamp_force, stiffness

    r = presentable_range(9.81)
    mat = SheetMaterial()
    assert r["limited_by"] == "arm_pull" and clamp_force(r["max_stretch"], mat) == pytest.approx(9.81, rel=1e-6)
    assert r["k_max_n_per_m"] == pytest.approx(stiffness(r["max_stretch"], mat))
    assert r["limits"]["strain"]["stretch"] == 0.30 and r["limits"]["strain"]["k_n_per_m"] > r["k_max_n_per_m"]
    assert presentable_range(1e4)["limited_by"] == "strain"
    res = run(tmp_path, "launch/scenes/organ.yaml")
    s, rng = res["scale"], res["range"]
    assert s * res["requested_along_stroke"]["k_max_n_per_m"] == pytest.approx(rng["k_max_n_per_m"])
    t = res["push"]["tumour"]
    k, kp = np.asarray(t["k_requested_n_per_m"]), np.asarray(t["k_presented_n_per_m"])
    inside = s * k > rng["k_min_n_per_m"]
    assert inside.any() and np.allclose(kp[inside], s * k[inside])          # ratios kept inside the range
    assert np.all(kp[~inside] == rng["k_min_n_per_m"])                       # the floor below it
    for c in res["tumour_contrast"]:
        assert c["felt"] == (c["presented"] >= 0.23) and c["presented"] <= c["asked"] + 1e-12
    assert (tmp_path / "compliance.png").stat().st_size > 5000
