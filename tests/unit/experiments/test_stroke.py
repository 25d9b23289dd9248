"""``flexsheet experiment stroke`` on the graph (flexsheet.experiments.stroke): the aggregate over seeds."""

from __future__ import annotations


def test_graph_stroke_judges_every_row_by_its_worst_seed():
    """flexsheet experiment stroke's aggregate: a row is met only when every seed meets it; a seed missing a
    row leaves that row unmeasured (MISSED)."""
    from flexsheet.experiments.stroke import aggregate

    def run(felt10, felt30, paper10):
        return {"table1":
                    {"felt": {"10": {"dtheta_mean_deg": felt10, "n": 400}, "30": {"dtheta_mean_deg": felt30}},
                     "paper": {"10": {"dtheta_mean_deg": paper10}}},
                "delay": {"exposure_to_sheet_ms": 24.0}}

    a = aggregate({0: run(0.10, 0.10, 0.05), 1: run(0.17, 0.12, 0.08), 2: run(0.15, 0.05, 0.02)})
    assert a["table1"]["felt"]["10"]["dtheta_mean_deg"] == 0.17 and a["table1"]["felt"]["30"][
        "dtheta_mean_deg"] == 0.12
    assert a["verdicts"]["felt.10"] == "met"                       # 0.17 <= 0.1795
    assert a["verdicts"]["felt.30"] == "MISSED"                    # seed 1: 0.12 > 0.1125
    assert a["verdicts"]["paper.10"] == "met" and a["verdicts"]["paper.30"].startswith("MISSED (not measured")
    assert a["table1"]["felt"]["10"]["per_seed"][1]["n"] == 400 and set(a["delay"]) == {0, 1, 2}
