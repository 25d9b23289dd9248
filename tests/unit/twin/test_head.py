"""The simulated viewer's head: sway within its bounds, the lean-in, occlusions, the eyes in the glasses."""

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.twin.head import HeadMotion, Viewer
from flexsheet.vision.glasses import tracked_eyes


def test_sway_stays_within_its_amplitudes_and_moves_centimetres():
    h = HeadMotion(Viewer.draw(3), seed=3)
    E = np.array([h.state(t).eye for t in np.arange(0.0, 120.0, 0.05)]) - geometry.EYE
    assert np.all(np.abs(E) <= np.array([0.05, 0.05, 0.03]) + 1e-12)
    assert np.all(E.max(0) - E.min(0) > [0.02, 0.02, 0.01])        # it does move, by centimetres


def test_lean_in_reaches_its_depth_and_comes_back():
    h = HeadMotion(Viewer.draw(0, "ideal"), still=True, lean_in=(10.0, 0.24, 2.0))
    assert h.state(9.0).eye == pytest.approx(geometry.EYE)
    assert h.state(12.5).eye[0] == pytest.approx(0.40 - 0.24, abs=1e-12)
    assert h.state(16.0).eye == pytest.approx(geometry.EYE)
    v = max(np.linalg.norm(h.state(t).velocity) for t in np.arange(10.0, 11.5, 0.01))
    assert v == pytest.approx(1.875 * 0.24 / 1.5, rel=0.01)          # minimum jerk: peak 1.875 d/T


def test_eyes_sit_at_the_viewers_offset_and_ipd_in_the_glasses():
    viewer = Viewer.draw(5)
    h = HeadMotion(viewer, seed=5, occlusions=((1.0, 0.5),))
    s = h.state(7.3)
    left, right, V = tracked_eyes(s.T_display_glasses, viewer.eye_offset, viewer.ipd)
    assert np.allclose(left, s.left) and np.allclose(right, s.right) and np.allclose(V, s.eye)
    assert np.linalg.norm(s.left - s.right) == pytest.approx(viewer.ipd)
    assert s.left[1] < s.right[1]              # the viewer's left is -y
    assert not h.state(1.2).visible and h.state(1.6).visible


def test_viewers_differ_by_seed_and_bad_scripts_are_refused():
    a, b = Viewer.draw(0), Viewer.draw(1)
    assert a.ipd != b.ipd and 0.054 <= a.ipd <= 0.072
    with pytest.raises(ValueError, match="occlusions"):
        HeadMotion(a, occlusions=((1.0, 0.0),))
    with pytest.raises(ValueError, match="realism"):
        Viewer.draw(0, "dreamy")
