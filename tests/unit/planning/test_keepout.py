"""The viewer's keep-out volume (flexsheet.planning.keepout): clearances of the home sheet and arms from the
nominal and a leaned-in head, computed by hand from the geometry; point–segment distances; the speed switch;
the retreat move; input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.planning.keepout import (
    CLAMP_DEPTH,
    CLAMP_REACH,
    KeepOut,
    arm_clearance,
    arm_segments,
    check_targets,
    retreat_point,
    sheet_points,
)

KO = KeepOut()
R_KO = 0.10 + 0.05                                   # head radius + margin (defaults)
HOME = dict(origin=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0), axis_u=(0.0, 1.0, 0.0), half_span=0.12)


@pytest.fixture(scope="module")
def arms():
    """(kin, q) of both arms at their home joints."""
    return {"left": (ArmKinematics("left", LEFT_BASE), home_joints("left")),
            "right": (ArmKinematics("right", RIGHT_BASE), home_joints("right"))}


def _segs(arms):
    return {f"{side} arm": arm_segments(k, q) for side, (k, q) in arms.items()}


def _hand(eye_x):
    """Hand-computed clearances for the home sheet and arms, eye at (eye_x, 0, 0): head centre C = (eye_x +
    0.08, 0, 0.02). Sheet: nearest point (0, 0, 0.02) (on the 0.02 m grid) → C_x − R. Clamp bars: nearest (0,
    ±0.12, 0.02) → √(C_x² + 0.12²) − R. Arm: the flange face (0, ±0.15, 0) (clamp jaw at (0, ±0.12, 0), clamp
    0.030 m long along ±y), link radius 0.05 m → √(C_x² + 0.15² + 0.02²) − R − 0.05.
    """
    cx = eye_x + 0.08
    return cx - R_KO, math.hypot(cx, 0.12) - R_KO, math.sqrt(cx ** 2 + 0.15 ** 2 + 0.02 ** 2) - R_KO - 0.05


def test_nominal_head_keeps_the_home_sheet_and_arms_clear(arms):
    V = (0.4, 0.0, 0.0)
    sheet_c, clamp_c, arm_c = _hand(0.4)
    assert (sheet_c, clamp_c, arm_c) == pytest.approx((0.33, 0.3447727, 0.3032892), abs=1e-6)
    pts = sheet_points(**HOME)
    assert KO.clearance(V, pts["sheet"]) == pytest.approx(sheet_c, abs=1e-12)
    assert KO.clearance(V, pts["left clamp"]) == pytest.approx(clamp_c, abs=1e-12)
    assert KO.clearance(V, pts["right clamp"]) == pytest.approx(clamp_c, abs=1e-12)
    for side in ("left", "right"):                       # home joints are given to 0.01 deg: 1e-4 m
        assert arm_clearance(KO, V, *arms[side]) == pytest.approx(arm_c, abs=1e-4)
    v = check_targets(KO, V, pts, _segs(arms))
    assert v.clearance == pytest.approx(arm_c, abs=1e-4)
    assert v.what.endswith("arm link 6") and not v.inside and v.speed_limit == math.inf


def test_eye_at_quarter_metre_is_still_at_full_speed(arms):
    V = (0.25, 0.0, 0.0)
    sheet_c, _, arm_c = _hand(0.25)
    assert (sheet_c, arm_c) == pytest.approx((0.18, 0.1630427), abs=1e-6)
    v = check_targets(KO, V, sheet_points(**HOME), _segs(arms))
    assert v.clearance == pytest.approx(arm_c, abs=1e-4)
    assert v.clearance > KO.near_distance and v.speed_limit == math.inf and not v.inside


def test_eye_at_015_is_near_but_outside(arms):
    # the head centre is 0.08 m behind the eye, so an eye 0.15 m from the sheet leaves 0.08 m of clearance
    V = (0.15, 0.0, 0.0)
    sheet_c, _, arm_c = _hand(0.15)
    assert (sheet_c, arm_c) == pytest.approx((0.08, 0.0753180), abs=1e-6)
    pts = sheet_points(**HOME)
    assert KO.clearance(V, pts["sheet"]) == pytest.approx(0.08, abs=1e-12)
    v = check_targets(KO, V, pts, _segs(arms))
    assert v.clearance == pytest.approx(arm_c, abs=1e-4)
    assert not v.inside and v.speed_limit == 0.25


def test_head_leaned_in_makes_the_sheet_violate(arms):
    V = (0.05, 0.0, 0.0)  # head centre (0.13, 0, 0.02): 0.02 m inside at the sheet
    v = check_targets(KO, V, sheet_points(**HOME), _segs(arms))
    assert v.inside and v.what == "sheet"
    assert v.clearance == pytest.approx(0.13 - R_KO, abs=1e-12)
    assert v.speed_limit == 0.25
    assert check_targets(KO, V, sheet_points(**HOME)["sheet"]).what == "sheet"   # bare array, no arms


@pytest.mark.parametrize("p, a, b, d", [
    ((0.5, 0.3, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.3),    # projects inside the segment
    ((-0.3, 0.4, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.5),   # beyond a: 3-4-5 to a
    ((1.6, 0.0, 0.8), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0),    # beyond b: 0.6-0.8-1 to b
    ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), 1.0),    # zero-length segment
    ((1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (2.0, 2.0, 0.0), 1.0),    # foot (1, 1, 0), off-axis segment
])
def test_point_segment_distance_hand_cases(p, a, b, d):
    ko = KeepOut(head_radius=0.1, margin=0.0, eye_to_head=(0.0, 0.0, 0.0))
    assert ko.clearance_segments(p, [a], [b]) == pytest.approx(d - 0.1, abs=1e-12)
    # several segments: the nearest one counts
    far = np.array([[10.0, 10.0, 10.0]])
    assert ko.clearance_segments(p, np.vstack([far, [a]]), np.vstack([far, [b]])) == pytest.approx(d - 0.1)


def test_arm_segment_clearance_matches_dense_sampling(arms):
    V = (0.3, 0.05, 0.1)
    c = KO.center(V)
    a, b = arm_segments(*arms["left"])
    t = np.linspace(0.0, 1.0, 20001)[:, None, None]
    sampled = np.linalg.norm(a + t * (b - a) - c, axis=2).min() - R_KO
    assert KO.clearance_segments(V, a, b) == pytest.approx(sampled, abs=1e-6)


def test_arm_segments_chain_and_shortened_tool_link(arms):
    kin, q = arms["left"]
    a, b = arm_segments(kin, q)
    p = kin.joint_origins(q)
    assert a.shape == b.shape == (7, 3)
    np.testing.assert_allclose(a, p[:-1])
    np.testing.assert_allclose(b[:-1], p[1:-1])
    assert np.linalg.norm(p[7] - b[6]) == pytest.approx(CLAMP_REACH, abs=1e-12)
    np.testing.assert_allclose(b[6], (0.0, 0.15, 0.0), atol=1e-4)


def test_speed_limit_switches_at_near_distance():
    assert KO.speed_limit(0.1499) == 0.25
    assert KO.speed_limit(0.15) == math.inf
    assert KO.speed_limit(-0.05) == 0.25
    assert KO.speed_limit(1.0) == math.inf
    with pytest.raises(ValueError, match="clearance"):
        KO.speed_limit(float("nan"))


def test_sheet_points_layout():
    pts = sheet_points(**HOME)
    assert pts["sheet"].shape == (169, 3) and pts["left clamp"].shape == (26, 3)
    s = pts["sheet"]
    for corner in ((0.0, 0.12, 0.12), (0.0, -0.12, 0.12), (0.0, 0.12, -0.12), (0.0, -0.12, -0.12)):
        assert np.min(np.linalg.norm(s - corner, axis=1)) < 1e-12
    lc = pts["left clamp"]
    assert set(np.round(lc[:, 0], 12)) == {0.0, -CLAMP_DEPTH} and np.allclose(lc[:, 1], 0.12)
    assert np.allclose(pts["right clamp"][:, 1], -0.12)
    # a stretched, tilted sheet: every point in its plane, inside |u| <= a, spacing <= 0.02 m
    n = np.array([math.cos(0.5), 0.0, math.sin(0.5)])
    o = np.array([-0.01, 0.0, 0.02])
    s = sheet_points(o, n, (0.0, 1.0, 0.0), 0.13)["sheet"]
    assert np.abs((s - o) @ n).max() < 1e-12 and np.abs(s[:, 1]).max() == pytest.approx(0.13)
    assert s.shape == (14 * 13, 3)


def test_retreat_point_backs_off_along_minus_x():
    V = (0.15, 0.0, 0.0)                                  # plane 0.23 m from C; wants 0.15 + 0.15 = 0.30
    np.testing.assert_allclose(retreat_point(KO, V, (0, 0, 0), (1, 0, 0), 0.05), (-0.05, 0.0, 0.0))
    r = retreat_point(KO, V, (0, 0, 0), (1, 0, 0), 0.1)
    np.testing.assert_allclose(r, (-0.07, 0.0, 0.0), atol=1e-12)
    moved = sheet_points(r, (1, 0, 0), (0, 1, 0), 0.12)["sheet"]
    assert KO.clearance(V, moved) == pytest.approx(KO.near_distance, abs=1e-12)
    # already clear: stays; head not in front of the sheet: stays (caller holds)
    np.testing.assert_allclose(retreat_point(KO, (0.4, 0, 0), (0, 0, 0), (1, 0, 0), 0.1), (0, 0, 0))
    np.testing.assert_allclose(retreat_point(KO, (-0.2, 0, 0), (0, 0, 0), (1, 0, 0), 0.1), (0, 0, 0))
    # sheet tilted 60 deg: n·(C − o) = 0.5·0.23 + 0.866·0.02 = 0.1323, need (0.30 − 0.1323)/0.5 = 0.335 > step
    n60 = (0.5, 0.0, math.sqrt(3) / 2)
    np.testing.assert_allclose(retreat_point(KO, V, (0, 0, 0), n60, 0.2), (-0.2, 0.0, 0.0))


@pytest.mark.parametrize("kwargs, field", [
    ({"head_radius": 0.0}, "head_radius"), ({"margin": -0.01}, "margin"),
    ({"near_distance": float("nan")}, "near_distance"), ({"reduced_speed": -1.0}, "reduced_speed"),
    ({"eye_to_head": (0.0, 0.0)}, "eye_to_head"), ({"head_radius": float("inf")}, "head_radius"),
])
def test_bad_keepout_fields_raise(kwargs, field):
    with pytest.raises(ValueError, match=field):
        KeepOut(**kwargs)


def test_bad_call_inputs_raise(arms):
    pts = sheet_points(**HOME)
    with pytest.raises(ValueError, match="V"):
        KO.clearance((float("nan"), 0, 0), pts["sheet"])
    with pytest.raises(ValueError, match="points"):
        KO.clearance((0.4, 0, 0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="same"):
        KO.clearance_segments((0.4, 0, 0), np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="half_span"):
        sheet_points((0, 0, 0), (1, 0, 0), (0, 1, 0), 0.0)
    with pytest.raises(ValueError, match="normal"):
        sheet_points((0, 0, 0), (2, 0, 0), (0, 1, 0), 0.12)
    with pytest.raises(ValueError, match="arm_segs"):
        check_targets(KO, (0.4, 0, 0), pts, {"left arm": np.zeros((7, 3))})
    with pytest.raises(ValueError, match="link_radius"):
        check_targets(KO, (0.4, 0, 0), pts, link_radius=-0.01)
    with pytest.raises(ValueError, match="q"):
        arm_segments(arms["left"][0], np.zeros(5))
    with pytest.raises(ValueError, match="step"):
        retreat_point(KO, (0.15, 0, 0), (0, 0, 0), (1, 0, 0), 0.0)
