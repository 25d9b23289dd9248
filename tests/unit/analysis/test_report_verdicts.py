"""The verdicts (flexsheet.analysis.report_verdicts): more digits where figure and target round alike, the
headline of an empty summary."""

from __future__ import annotations

from flexsheet.analysis.report_verdicts import NO_TARGET, digits, headline, judge


def test_more_digits_where_figure_and_target_round_alike():
    assert digits(0.11312, 0.1125) == 4 and digits(0.1128, 0.1125) == 4 and digits(0.118, 0.1125) == 3
    assert digits(0.1125, 0.1125) == 3 and digits(0.11250001, 0.1125) == 6      # capped
    from flexsheet.analysis.report_text import format_text

    s = {"table1": {"felt": {"30": {"dtheta_mean_deg": 0.11312, "dtheta_std_deg": 0.09, "n": 1417}},
                    "targets": {"felt": {"30": 0.1125}}, "verdicts": {"felt.30": "MISSED"}},
         "segments": {"30": {"partial": False, "expected_n": 1440, "coverage": 1.0}}, "latency_ms": {}}
    judge(s)
    line = next(li for li in format_text(s).splitlines() if li.startswith("30 s"))
    assert "0.1131" in line and "0.1125" in line and "MISSED" in line and "+0.6 %" in line, line


def test_headline_of_an_empty_summary_has_no_rows():
    assert headline({}) == {"metric": headline({})["metric"], "target_source": "paper Table I ÷ 2",
                            "rows": {},
                            "overall": NO_TARGET}
