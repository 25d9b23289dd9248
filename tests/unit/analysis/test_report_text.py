"""The report's text (flexsheet.analysis.report_text): the one delay figure, Δd 2R left blank where a shape
has no radius."""

from __future__ import annotations


def test_report_text_leaves_dd_2r_blank_on_a_shape_with_no_radius():
    """The rounded box and the organ have no radius R, so their rows carry no Δd 2R: the text table prints "-"
    there (it printed "nan", which reads as a failed measurement), and the number where there is one."""
    from flexsheet.analysis.report_text import format_text as _format

    row = {"dtheta_mean_deg": 0.5, "dtheta_std_deg": 0.25, "dd_mean_mm": 1.25, "n": 120}
    text = _format({"10": row, "30": {**row, "dd_2r_mean_mm": 0.875}, "latency_ms": {}})
    line10 = next(li for li in text.splitlines() if li.startswith("10 s"))
    line30 = next(li for li in text.splitlines() if li.startswith("30 s"))
    assert line10.split()[2:6] == ["0.500", "0.250", "-", "1.250"], line10
    assert line30.split()[2:6] == ["0.500", "0.250", "0.875", "1.250"], line30


def test_the_delay_is_the_chains_figure():
    """The one delay figure is the latency chain's exposure → sheet at its pose; the fitted lag is named as
    the prediction check, with why the two differ."""
    from flexsheet.analysis.report_text import format_text

    s = {"latency_ms": {"chain": {"exposure_to_sheet_at_pose": {"median": 14.33, "p99": 29.29, "n": 838},
                                  "exposure_to_arm_command": {"median": 9.19, "p99": 9.19, "n": 1424}},
                        "sheet_at_pose_reached": 838 / 1424,
                        "basis": {"exposure_to_sheet_at_pose": {"basis": "modelled"}}},
         "delay": {"segment": "10", "horizon_ms": 25.0, "residual_lag_ms": -1.0, "exposure_to_sheet_ms": 24.0,
                   "angle_at_best_deg": 0.114, "stroke_speed_mm_per_s": 6.2}}
    text = format_text(s)
    delay = [li for li in text.splitlines() if li.startswith("The delay:")]
    assert (len(delay) == 1 and "median 14.3 ms (p99 29.3 ms, modelled" in delay[0]
            and "838 of 1424" in delay[0])
    check = next(li for li in text.splitlines() if li.startswith("Not a second delay"))
    assert "-1.0 ms beyond the prediction's 25.0 ms lead" in check and "horizon of 24.0 ms" in check
    assert "16 ms of travel" in check                                       # 0.1 mm at 6.2 mm/s
    assert "Delay exposure -> sheet" not in text


def test_the_clamps_against_the_motion_are_written_only_when_measured():
    """``sheet.path_dev_mm`` / ``arrival_skew_ms`` in the softness prose: both figures when measured; a run
    whose sheet never moved fast enough gets the deviation alone, said so, and a summary without them no
    line."""
    from flexsheet.analysis.report_text import sections

    band = {"median": 1.0, "p5": 1.0, "p95": 1.0}
    seg = {"tension_n_per_m": band, "stiffness_n_per_m": band, "object_stiffness_n_per_m": band,
           "at_limit": 0.0}

    def _softness(summary):
        summary["compliance"]["all"] = seg
        return next(body for title, *body in sections(summary) if title.startswith("Softness felt"))

    soft = {"n": 3, "ratio": {"median": 1.0, "p5": 0.9, "p95": 1.1}, "within_15pct": 1.0, "felt_n": 1.0,
            "requested_n": 1.0, "verdict": "met"}
    sheet = {"strain_true_max": 0.03, "strain_over_plan_max": 0.004, "one_arm_holds": 0, "verdict": "met",
             "path_dev_mm": {"median": 0.1, "p99": 0.53, "max": 1.65, "n": 100},
             "arrival_skew_ms": {"median": 0.0, "p99": 27.0, "max": 30.0, "n": 40}}
    text = " ".join(_softness({"compliance": {"felt": soft}, "sheet": sheet})[0])
    assert "p99 0.53 mm, max 1.65 mm" in text and "differs by p99 27 ms" in text
    sheet["arrival_skew_ms"] = {"median": None, "p99": None, "max": None, "n": 0}
    text = " ".join(_softness({"compliance": {"felt": soft}, "sheet": sheet})[0])
    assert "p99 0.53 mm" in text and "never moved fast enough" in text
    del sheet["path_dev_mm"], sheet["arrival_skew_ms"]
    assert "Each clamp" not in " ".join(_softness({"compliance": {"felt": soft}, "sheet": sheet})[0])
