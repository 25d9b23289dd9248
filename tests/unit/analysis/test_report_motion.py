"""The run report's sheet-motion figures (flexsheet/analysis/report_motion.py) from a hand-made bag: the true
span against the motion's at each instant (not the goal's), and the guards' cycles."""

from __future__ import annotations

import numpy as np

from flexsheet.analysis.report_motion import motion_summary
from flexsheet.arm.sheet_motion import SheetShaper
from flexsheet.model.sheet import sheet_rotation
from messages import ArmJointState, ArmTarget, SheetState
from messages.common import Header

R0 = sheet_rotation([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def _h(t: float) -> Header:
    return Header(stamp=t, frame_id="display", seq=0)


def _world(t: float, strain: float) -> SheetState:
    return SheetState(header=_h(t), origin=np.zeros(3), normal=np.array([1.0, 0, 0]),
                      axis_u=np.array([0, 1.0, 0]),
                      corners=np.zeros((4, 3)), pushed_point=np.zeros(3), depth=0.0, stretch=strain,
                      membrane=np.zeros((2, 2)))


def _joint(t: float, arm: str, status: str) -> ArmJointState:
    z = np.zeros(6)
    return ArmJointState(header=_h(t), arm=arm, position=z, velocity=z, commanded=z, executing=z,
                         pose=np.eye(4),
                         status=0, bridge_status=status)


def test_the_span_error_is_judged_against_the_motion_at_each_instant_and_guard_cycles_are_counted():
    sh = SheetShaper()
    sh.update(0.0, np.zeros(3), R0, 0.01)
    seg = sh.update(0.0, np.zeros(3), R0, 0.05)          # the strain ramps from 0.01 to 0.05
    ts = np.linspace(0.0, seg.duration + 0.2, 60)
    planned = np.array([seg.sheet(t)[2] for t in ts])
    true = planned + 0.002 / 0.24 * np.where(ts > 0.1, 1.0, 0.0)     # 2 mm long after 0.1 s
    d = {"/arm/left/target": [(0.0, ArmTarget(header=_h(0.0), arm="left", pose=np.eye(4), **seg.fields()))],
         "/world/sheet": [(t, _world(t, e)) for t, e in zip(ts, true, strict=True)],
         "/arm/left/joint_state": [(0.1, _joint(0.1, "left", "wait:span")), (0.2, _joint(0.2, "left", "ok"))],
         "/arm/right/joint_state": [(0.1, _joint(0.1, "right", "hold:peer"))]}
    s = motion_summary(d)
    n_long = int(np.sum(ts > 0.1))
    assert s["span_error_mm"]["n"] == 60
    assert np.isclose(s["span_error_mm"]["max"], 2.0) and np.isclose(s["span_error_mm"]["median"],
                                                                     2.0 if n_long > 30 else 0.0)
    assert s["guard_waits"] == 2 and s["motion_verdict"] == "MISSED"
    # judged against the goal's strain instead, the ramp itself would read as up to 9.6 mm of error
    assert abs(true[0] - 0.05) * 240 > 9.0
    assert motion_summary({"/world/sheet": d["/world/sheet"]}) == {}


def _pose_at(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _tracking_bag(lag_left: float, lag_right: float, offset_right=(0.0, 0.0, 0.0)) -> tuple[dict, object]:
    """A 100 mm move of the sheet; each arm's measured clamp is the motion's clamp ``lag`` s earlier."""
    sh = SheetShaper()
    sh.update(0.0, np.zeros(3), R0, 0.02)
    seg = sh.update(0.0, np.array([0.0, 0.0, 0.1]), R0, 0.02)
    ts = np.arange(0.0, seg.duration + 0.3, 0.0071)
    d = {"/arm/left/target": [(0.0, ArmTarget(header=_h(0.0), arm="left", pose=np.eye(4), **seg.fields()))],
         "/world/sheet": [(t, _world(t, seg.sheet(t)[2])) for t in ts]}
    for i, (side, lag) in enumerate((("left", lag_left), ("right", lag_right))):
        js = []
        for t in ts:
            p = seg.clamp_points(max(t - lag, 0.0))[i] + (np.asarray(offset_right) if side == "right"
                                                          else 0.0)
            m = _joint(t, side, "ok")
            js.append((t, m.model_copy(update={"pose": _pose_at(p)})))
        d[f"/arm/{side}/joint_state"] = js
    return d, seg


def test_the_clamps_lag_behind_the_motion_is_compared_between_the_arms_and_the_path_deviation_measured():
    d, seg = _tracking_bag(0.030, 0.080)
    s = motion_summary(d)
    sk, pd = s["arrival_skew_ms"], s["path_dev_mm"]
    assert sk["n"] > 20 and abs(sk["median"] - 50.0) <= 2.5, sk        # 80 − 30 ms, on a 2 ms grid
    # the deviation at the same instant is the distance travelled in the lag: at most v_max · 80 ms
    ts = np.linspace(0.0, seg.duration, 400)
    v = np.linalg.norm(np.diff([seg.clamp_points(t)[1] for t in ts], axis=0), axis=1) / np.diff(ts)
    assert 0.9 * v.max() * 0.080e3 <= pd["max"] <= 1.05 * v.max() * 0.080e3 + 0.1, (pd, v.max())
    # both arms equally late: no skew, though each is off the path at the same instant
    s2 = motion_summary(_tracking_bag(0.05, 0.05)[0])
    assert s2["arrival_skew_ms"]["p99"] <= 2.0 and s2["path_dev_mm"]["max"] > 5.0
    # on time, but the right clamp 3 mm off the path: no skew, 3 mm deviation
    s3 = motion_summary(_tracking_bag(0.0, 0.0, (0.003, 0.0, 0.0))[0])
    assert s3["arrival_skew_ms"]["p99"] <= 2.0 and abs(s3["path_dev_mm"]["max"] - 3.0) < 0.05
