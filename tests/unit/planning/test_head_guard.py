"""The planner's head guard: normal limits far from the head, reduced ones near it, a back-off before the
keep-out."""

import numpy as np
import pytest

from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.sheet import clamp_half_span
from flexsheet.planning.head_guard import HeadGuard

R_HOME = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]])      # columns n = +x, u = +y, v = +z


def test_inactive_until_an_eye_then_lost_only_after_one():
    g = HeadGuard()
    g.set_eye([0.4, 0, 0], False)
    assert g.state == "inactive" and not g.lost           # no head camera yet: nothing to hold for
    g.set_eye([0.4, 0, 0], True)
    assert g.state == "tracking"
    g.set_eye([0.4, 0, 0], False)
    assert g.state == "lost"
    with pytest.raises(ValueError, match="eye"):
        g.set_eye([0.4, np.nan, 0], True)


def test_limits_drop_near_the_head_so_no_sheet_point_exceeds_250_mm_s():
    g = HeadGuard()
    base = MotionLimits()
    g.set_eye([0.40, 0, 0], True)
    assert g.limits(base, (0.0, 0, 0), R_HOME, 0.02) == base          # home sheet, viewer at V: far (0.33 m)
    g.set_eye([0.20, 0, 0], True)                                    # head sphere front 0.18, keep-out 0.13
    near = g.limits(base, (0.0, 0, 0), R_HOME, 0.02)
    corner = np.hypot(0.12, 0.12)
    assert near.v_max + near.w_max * corner + near.stretch_rate * 0.12 <= 0.9 * 0.25 + 1e-12
    assert near.a_max == base.a_max and g.counts["near"] == 1 and g.near


def test_a_step_into_the_keep_out_backs_off_along_minus_x():
    g = HeadGuard()
    g.set_eye([0.10, 0, 0], True)           # head centre (0.18, 0, 0.02): guarded boundary at x = 0.02
    st = g.step((0.0, 0, 0), R_HOME, (0.05, 0, 0), R_HOME, 0.02, 0.02)
    assert st.retreat and g.counts["retreat"] == 1
    assert st.origin[0] == pytest.approx(-0.45 * 0.25 * 0.02)         # one reduced-speed step back
    assert np.allclose(st.R, R_HOME)
    ok = g.step((0.0, 0, 0), R_HOME, (-0.01, 0, 0), R_HOME, 0.02, 0.02)
    assert not ok.retreat and ok.origin[0] == pytest.approx(-0.01)
    # the verdict measures the sheet's nearest point: the centre grid point 0.03 m from the boundary
    assert ok.verdict.clearance == pytest.approx(np.linalg.norm([0.18 + 0.01, 0, 0.02]) - 0.16, abs=2e-3)
    assert clamp_half_span(0.02) > 0.12


def test_lost_while_near_backs_off_every_step():
    g = HeadGuard()
    g.set_eye([0.20, 0, 0], True)
    g.limits(MotionLimits(), (0.0, 0, 0), R_HOME, 0.02)
    assert g.near
    g.set_eye([0.20, 0, 0], False)
    st = g.step((0.0, 0, 0), R_HOME, (-0.001, 0, 0), R_HOME, 0.02, 0.02)     # even a harmless step
    assert st.retreat and st.origin[0] < 0.0
