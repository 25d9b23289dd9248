"""``flexsheet experiment compliance`` (flexsheet.experiments.compliance): the object's force-depth from its
FEM, the presentable range from the arms' torque and the sheet, one scale per scene, and the contrast a finger
feels."""

from __future__ import annotations

import json

import numpy as np
import pytest


def test_the_organ_maps_into_the_range_keeping_its_tumour_contrast_and_the_gain_raises_it(tmp_path):
    from flexsheet.experiments.compliance import main, presentable_range

    rng = presentable_range()
    assert rng["limited_by"] == "arm_torque" and 25.0 < rng["pull_n"] < 40.0     # 0.9 x 33.5 N at home (J3)
    assert rng["clamp_force_at_max_n"] == pytest.approx(rng["pull_n"], rel=1e-6)
    assert main(["--scene", "launch/scenes/organ.yaml", "--out", str(tmp_path / "g1")]) == 0
    res = json.loads((tmp_path / "g1" / "compliance.json").read_text())
    fd = json.loads((tmp_path / "g1" / "force_depth.json").read_text())
    assert fd["points"][0]["name"] == "reference" and fd["hertz_check"] is None
    assert res["fits"] and res["saturated"] == 0.0 and res["scale_low"] <= res["scale"] <= res["scale_high"]
    top = next(p for p in res["points"] if p["name"] == res["stiffest_point"]["name"])
    asked, pres = np.asarray(top["contrast_asked"]), np.asarray(top["contrast_presented"])
    assert np.median(asked) > 0.15                       # the FEM's tumour: above the Weber fraction
    assert np.allclose(pres, asked, atol=1e-9)           # faithful inside the range: every ratio kept
    assert (
        main(["--scene", "launch/scenes/organ.yaml", "--contrast-gain", "2.5", "--out", str(tmp_path / "g2")])
            == 0)
    res2 = json.loads((tmp_path / "g2" / "compliance.json").read_text())
    top2 = next(p for p in res2["points"] if p["name"] == top["name"])
    inside = np.asarray(top2["requested_n"]) == np.asarray(top2["presented_n"])
    want = (1.0 + asked) ** 2.5 - 1.0
    assert (inside.any()
            and np.allclose(np.asarray(top2["contrast_presented"])[inside], want[inside], rtol=1e-6))
    assert (tmp_path / "g1" / "compliance.png").stat().st_size > 5000


def test_bad_arguments_are_refused_with_a_clear_message(tmp_path, capsys):
    from flexsheet.experiments.compliance import main

    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--contrast-gain", "0"])
    assert "--contrast-gain must be in (0, 5]" in capsys.readouterr().err
    assert main(["--out", str(tmp_path), "--sheet", str(tmp_path / "missing.json")]) == 2
    assert "--sheet" in capsys.readouterr().err
