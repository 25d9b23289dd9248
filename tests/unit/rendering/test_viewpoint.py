"""The renderer's choice of eyes: tracked and predicted to photon time, held while lost, then the fixed V."""

import numpy as np
import pytest

from flexsheet.rendering.viewpoint import Viewpoint

FL, FR = np.array([0.4, -0.032, 0.0]), np.array([0.4, 0.032, 0.0])


def test_fixed_until_the_first_pose_then_tracked_and_predicted():
    vp = Viewpoint(FL, FR, hold=2.0, timeout=0.1, max_extrapolation=0.1)
    c = vp.eyes(1.0)
    assert c.source == "fixed" and np.allclose(c.left, FL) and "fixed" in c.say
    vp.update(1.0, FL + [0, 0.01, 0], FR + [0, 0.01, 0], [0.0, 0.2, 0.0], True)
    c = vp.eyes(1.03)                      # 30 ms later at 0.2 m/s: 6 mm on
    assert c.source == "tracked" and c.say
    assert c.left[1] == pytest.approx(-0.032 + 0.01 + 0.006, abs=1e-12)
    assert vp.eyes(1.05).say == ""        # said once
    c = vp.eyes(1.25)                      # 0.25 s old: beyond timeout + max extrapolation → held, unmoved
    assert c.source == "held" and c.left[1] == pytest.approx(-0.022, abs=1e-12)


def test_lost_glasses_hold_the_last_pose_then_fall_back_to_v():
    vp = Viewpoint(FL, FR, hold=2.0)
    vp.update(10.0, FL + 0.02, FR + 0.02, np.zeros(3), True)
    vp.update(10.02, FL, FR, np.zeros(3), False)
    c = vp.eyes(10.05)
    assert c.source == "held" and np.allclose(c.left, FL + 0.02) and "lost" in c.say
    c = vp.eyes(12.5)
    assert c.source == "fixed" and np.allclose(c.right, FR)
    vp.update(12.6, FL + 0.01, FR + 0.01, np.zeros(3), True)
    assert vp.eyes(12.61).source == "tracked"
    assert vp.counts == {"tracked": 1, "held": 1, "fixed": 1}


def test_bad_inputs_are_refused_naming_the_field():
    with pytest.raises(ValueError, match="fixed_left"):
        Viewpoint([0.4, np.nan, 0], FR)
    with pytest.raises(ValueError, match="hold"):
        Viewpoint(FL, FR, hold=0.0)
    vp = Viewpoint(FL, FR)
    with pytest.raises(ValueError, match="velocity"):
        vp.update(1.0, FL, FR, [0, np.inf, 0], True)
    assert vp.eyes(1.0).source == "fixed"          # the bad pose was not kept
