"""Table I's metrics (flexsheet.analysis.table1): the Fig. 9 definitions of Δd and Δθ, the summary's
medians, the rows from sheet poses on the cylinder."""

import math

import numpy as np
import pytest

from flexsheet.analysis.table1 import stroke_errors, summarize, table1
from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder

R = geometry.CYLINDER_RADIUS


def test_metrics_fig9_definitions():
    D = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    Dp = np.array([[0.0, 0.0, 0.001], [0.0, 0.0, 0.0]])
    n = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    a = math.radians(1.0)
    n2 = np.array([[1.0, 0, 0], [math.cos(a), 0, math.sin(a)]])
    dd, dth = stroke_errors(D, Dp, n, n2)
    assert dd == pytest.approx([0.001, 0.0]) and dth == pytest.approx([0.0, a])
    s = summarize(dd, dth)
    assert s["dd_mean_mm"] == pytest.approx(0.5) and s["dtheta_mean_deg"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="Dp"):
        stroke_errors(D, Dp[:1], n, n2)
    # the median ignores a stalled stretch that lifts the mean: 9 samples of 0.5 mm and one of 20 mm
    s = summarize(np.r_[np.full(9, 0.0005), 0.02], np.r_[np.full(9, a / 2), 10 * a])
    assert s["dd_median_mm"] == pytest.approx(0.5) and s["dd_mean_mm"] == pytest.approx(2.45)
    assert s["dtheta_median_deg"] == pytest.approx(0.5) and s["dtheta_mean_deg"] == pytest.approx(1.45)


def test_table1_from_sheet_poses_on_cylinder():
    c = paper_cylinder()
    ang = np.radians([0.0, 10.0, 30.0])
    lag = math.radians(0.5)
    meas = np.array([c.point_at(a, 0.0, R + 0.002) for a in ang])
    sheet_n = np.array([[math.cos(a - lag), 0.0, -math.sin(a - lag)] for a in ang])
    sheet_o = np.array([c.point_at(a - lag) for a in ang])
    err = table1(c, meas, sheet_o, sheet_n)
    assert err.dtheta == pytest.approx([lag] * 3, abs=1e-12)
    assert err.dd == pytest.approx([2 * R * math.sin(lag / 2)] * 3, abs=1e-12)
    assert np.abs(err.gap).max() < 1e-12
