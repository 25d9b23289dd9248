"""The report's charts (flexsheet.analysis.report_charts): targets belong to the paper's cylinder, the
spread clipped at 0."""

from __future__ import annotations

import json

import pytest

from flexsheet.analysis.report_verdicts import NO_TARGET, judge


def test_targets_belong_to_the_paper_cylinder_and_the_chart_clips_the_spread(tmp_path):
    """Another scene (its verdicts empty): no paper row, no target, verdict "no target"; the chart draws this
    scene's rows only and the spread of a row whose s.d. exceeds its mean stops at 0."""
    from flexsheet.analysis.report_charts import latency_chart, table1_chart

    felt = {"dtheta_mean_deg": 0.6, "dtheta_std_deg": 0.9, "dd_mean_mm": 1.2, "dd_std_mm": 2.0, "n": 400}
    s = {"scene": {"name": "organ"}, "table1": {"felt": {"10": felt}, "targets": {}, "verdicts": {}},
         "segments": {"10": {"partial": False}}, "run": {"partial": False},
         "latency_ms": {"chain": {"exposure_to_arm_command": {"median": 15.5, "p99": 16.0, "n": 10}}}}
    judge(s)
    r = s["headline"]["rows"]["10"]
    assert r["verdict"] == NO_TARGET and r["published_deg"] is None and r["target_deg"] is None
    assert "not this scene" in r["target_source"] and s["headline"]["overall"] == NO_TARGET
    data = table1_chart(s, tmp_path / "table1.png")
    row = data["rows"]["10"]
    assert row["dtheta_spread_deg"] == (0.0, 1.5) and row["dd_spread_mm"] == (0.0, pytest.approx(3.2))
    assert row["published_dd_mm"] is None and "organ" in data["title"] and data["units"]["dd"] == "mm"
    assert (tmp_path / "table1.png").stat().st_size > 5000
    assert json.loads((tmp_path / "table1.json").read_text())["overall"] == NO_TARGET
    assert s["latency_ms"]["targets"]["exposure_to_arm_command"]["verdict"] == "MISSED"    # 15.5 > 15 ms
    lat = latency_chart(s, tmp_path / "latency.png")
    assert lat["unit"] == "ms" and lat["rows"]["exposure_to_arm_command"]["target_ms"] == 15.0
    assert (tmp_path / "latency.png").stat().st_size > 5000
