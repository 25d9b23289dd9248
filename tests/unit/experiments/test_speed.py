"""The speed experiment's arithmetic (flexsheet.experiments.speed): the accuracy figures read from a run's
summary, and a cut's point judged against the two truths' spread."""

import pytest

from flexsheet.experiments.speed import FIGURES, cut_point, figures

SUMMARY = {"eye": {"error_mm": {"median": 1.3}},
           "table1": {"felt": {"10": {"dtheta_mean_deg": 0.20}, "30": {"dtheta_mean_deg": 0.13}}},
           "placement": {"distance_mm": {"p99": 0.4}},
           "compliance": {"felt": {"within_15pct": 0.92}}}


def test_figures_take_the_longest_table_row_and_the_force_outside_the_band():
    f = figures(SUMMARY)
    assert f == pytest.approx({"eye_error_median_mm": 1.3, "felt_dtheta_mean_deg": 0.13,
                               "placement_p99_mm": 0.4, "force_outside_15pct": 0.08})
    short = figures({**SUMMARY, "table1": {"felt": {"10": {"dtheta_mean_deg": 0.2}}}, "compliance": {}})
    assert short["felt_dtheta_mean_deg"] == 0.2 and short["force_outside_15pct"] is None
    assert set(f) == set(FIGURES)


def _run(cpu, figs, hashes):
    return {"cpu_per_sim_s": cpu, "figures": figs, "hashes": hashes}


def test_a_cut_is_kept_only_while_no_figure_moves_beyond_the_spread():
    base = _run(2.0, figures(SUMMARY), {"/a": 1})
    noise = {"eye_error_median_mm": 0.1, "felt_dtheta_mean_deg": 0.01, "placement_p99_mm": 0.05,
             "force_outside_15pct": None}
    same = cut_point("same", base, _run(1.5, figures(SUMMARY), {"/a": 1}), noise)
    assert same["verdict"] == "kept" and same["identical_bytes"]
    assert same["cpu_saved_per_sim_s"] == pytest.approx(0.5)
    assert same["cpu_saved_share"] == pytest.approx(0.25)
    worse = dict(figures(SUMMARY), felt_dtheta_mean_deg=0.15, eye_error_median_mm=1.35)
    p = cut_point("worse", base, _run(1.0, worse, {"/a": 2}), noise)
    assert p["verdict"] == "costs accuracy" and p["moved_beyond_noise"] == ["felt_dtheta_mean_deg"]
    assert p["delta"]["felt_dtheta_mean_deg"] == pytest.approx(0.02) and not p["identical_bytes"]
