"""Table I from a recorded bag (flexsheet.analysis.report_analysis): the typed truth picks the stroking
segments and the row matches the errors built into synthetic data (the sheet lagging the finger by a known
angle); a paused stroke counts once, a cut one as partial."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.analysis.report_analysis import analyse
from flexsheet.analysis.table1 import PAPER_TABLE1
from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import Fingertip, FingerTruth, Header, SheetState
from messages import topics as T

R = geometry.CYLINDER_RADIUS
LAG = math.radians(0.5)
OMEGA = math.radians(6.0)          # 60° in 10 s


def _angle(t: float) -> float:
    return OMEGA * max(0.0, t - 1.0)


def _write_bag(path, t_end: float = 3.0) -> int:
    """A fake run: truth at 100 Hz (approach for 1 s, then 'stroke' of a 10 s segment, then a 'stroke_push'
    segment from 2.5 s), fingertips at 48 Hz 2 mm outside the cylinder (one invalid), sheet states at 100 Hz
    tangent at the finger's angle minus LAG. Returns the number of valid fingertips in the 10 s stroke."""
    c = paper_cylinder()
    w = BagWriter(path)
    n_stroke = 0

    def put(topic, msg, t):
        w.write(encode(topic, msg), int(t * 1e9))

    for k, t in enumerate(np.arange(0.0, t_end, 0.01)):
        seg, mode, mt = (0, "stroke", 10.0) if t < 2.5 else (1, "stroke_push", 4.0)
        phase = "approach" if t < 1.0 else mode
        a = _angle(t)
        put(T.FINGER_TRUTH.name,
            FingerTruth(header=Header(stamp=t, seq=k), position=np.array(c.point_at(a, 0.0, R)),
                        velocity=np.zeros(3), segment=seg, mode=mode, moving_time=mt,
                        phase=phase), t)
        b = a - LAG
        n = np.array([math.cos(b), 0.0, -math.sin(b)])     # point_at: positive angles go down (−z)
        o = np.array(c.point_at(b))
        put(T.SHEET_STATE.name, SheetState(header=Header(stamp=t, seq=k), origin=o, normal=n,
                                           axis_u=np.array([0.0, 1.0, 0.0]), corners=np.zeros((4, 3)),
                                           pushed_point=o, depth=0.0, stretch=0.02,
                                           membrane=np.zeros((2, 2))), t)
    for k, t in enumerate(np.arange(0.005, t_end - 0.02, 1.0 / 48.0)):
        valid = k != 60
        p = np.array(c.point_at(_angle(t), 0.0, R + 0.002))
        put(T.FINGERTIP.name, Fingertip(header=Header(stamp=t, seq=k), position=p if valid else np.zeros(3),
                                        covariance=np.eye(3) * 1e-8, valid=valid,
                                        predicted_position=np.zeros(3),
                                        exposure_stamp=float(t)), t + 0.01)
        n_stroke += valid and 1.0 <= t < 2.5
    w.close()
    return n_stroke


def test_report_table1_from_bag_uses_typed_truth_and_the_one_metric(tmp_path):
    n_stroke = _write_bag(tmp_path / "run.mcap")
    s = analyse(tmp_path / "run.mcap")
    assert s["counts"][T.FINGERTIP.name] > 100 and s["fingertip_invalid"] == 1
    row = s["10"]
    assert row["n"] == n_stroke  # only the 'stroke' phase of the 10 s segment
    # the sheet lags by LAG around the axis: Δθ = LAG, Δd = chord 2R sin(LAG/2) (Fig. 9 on the surface)
    assert row["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-4)
    assert row["dd_mean_mm"] == pytest.approx(2e3 * R * math.sin(LAG / 2), abs=1e-4)
    assert row["dd_std_mm"] < 1e-4 and row["gap_mean_mm"] < 1e-4     # 100 Hz sheet: interpolation only
    assert row["paper"] == PAPER_TABLE1["10"]
    push = s["stroke_push_4"]                                     # the second segment, keyed by its mode
    assert push["n"] >= 10 and "paper" not in push
    assert set(s["latency_ms"]["chain"]) >= {"fingertip_to_sheet_target", "exposure_to_arm_command",
                                             "exposure_to_projected"}
    # felt: the true finger against the true sheet, here the same lag; the 3-D angle equals the
    # section angle (the sheet's normal lies in the section); no joint readback in this bag: no paper row
    felt = s["table1"]["felt"]["10"]
    assert felt["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-3) and felt["n"] == n_stroke
    assert felt["angle3d_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-3)
    assert s["table1"]["paper"] == {}
    assert s["table1"]["verdicts"] == {"felt.10": "MISSED"}                 # 0.5° against 0.359 / 2
    dc = s["table1"]["decomposition"]["10"]  # no tremor, camera error only along the normal: the lag is all
    assert (dc["tremor"] < 0.01 and dc["camera"] < 0.01
            and dc["slow_finger"] == pytest.approx(math.degrees(LAG), abs=0.01))
    assert s["table1"]["targets"]["felt"]["10"] == pytest.approx(PAPER_TABLE1["10"]["dtheta_mean_deg"] / 2)
    # the sheet trails the finger by LAG at OMEGA: LAG / OMEGA = 83.3 ms, found by the lag fit (1 ms grid)
    assert s["delay"]["segment"] == "10" and s["delay"]["horizon_ms"] == 0.0
    assert s["delay"]["exposure_to_sheet_ms"] == pytest.approx(1e3 * LAG / OMEGA, abs=1.0)
    assert s["delay"]["angle_at_best_deg"] < 0.03                         # against 0.5 deg unaligned


def test_segments_count_a_paused_stroke_once_and_a_cut_one_as_partial():
    """stroke_segments on a truth at 100 Hz: a 10 s stroke paused for 5 s midway is one pass whose moved time
    excludes the pause; a 30 s stroke the bag ends in is partial, with its share of the moving time."""
    from types import SimpleNamespace as NS

    from flexsheet.analysis.report_analysis import stroke_segments

    def truth(t, seg, mt, phase):
        return (t, NS(header=NS(stamp=t), segment=seg, mode="stroke", moving_time=mt, phase=phase))

    ts = np.arange(0.0, 30.0, 0.01)
    tr = [truth(t, 0, 10.0, "approach" if t < 1 else "idle" if t < 2 else "paused" if 6 <= t < 11
                else "stroke" if t < 17 else "idle") for t in ts if t < 18]
    tr += [truth(t, 1, 30.0, "approach" if t < 19 else "idle" if t < 20 else "stroke") for t in ts if t >= 18]
    tips = [(t, NS(exposure_stamp=t)) for t in np.arange(0.0, 30.0, 1 / 48)]
    seg, run = stroke_segments(tr, tips)
    assert seg["10"]["passes"] == 1 and seg["10"]["moved_s"] == pytest.approx(10.0, abs=0.05)
    assert not seg["10"]["partial"] and seg["10"]["expected_n"] == 480
    assert seg["30"]["partial"] and seg["30"]["coverage"] == pytest.approx(10.0 / 30.0, abs=0.01)
    assert run["partial"] and "segment 30 s" in run["note"] and "33 %" in run["note"]


def test_the_felt_error_splits_additively_by_the_planners_status_and_names_the_largest():
    from types import SimpleNamespace

    from flexsheet.analysis.report_analysis import felt_by_status, plan_statuses, status_class

    assert status_class("rate_limited;ik:left:limit:J3;unreachable") == "unreachable"
    assert status_class("rate_limited;reach:nearest") == "nearest"
    assert status_class("hold:head_lost") == "hold" and status_class("ok") == "ok"
    t = np.arange(10) * 0.02
    status = ["ok"] * 6 + ["rate_limited;ik:left:limit:J3;unreachable"] * 3      # the last fingertip: no plan
    plans = [(0.0, SimpleNamespace(source_stamp=float(x), status=s))
             for x, s in zip(t[:9], status, strict=True)]
    dtheta = np.array([0.2] * 6 + [8.0] * 3 + [1.0])
    split = felt_by_status(plan_statuses({"/sheet/target": plans}), t, dtheta)
    assert split["unreachable"]["share"] == pytest.approx(0.3)
    assert split["unreachable"]["mean_deg"] == pytest.approx(8.0)
    assert split["unreachable"]["of_mean"] == pytest.approx(24.0 / 26.2)
    assert split["no plan"]["share"] == pytest.approx(0.1)
    assert sum(v["of_mean"] for v in split.values()) == pytest.approx(1.0)
    # the shares times the means give the felt mean back
    assert sum(v["share"] * v["mean_deg"] for v in split.values()) == pytest.approx(dtheta.mean())


def test_the_force_misses_split_by_the_plan_in_force_at_each_sample():
    from types import SimpleNamespace

    from flexsheet.analysis.report_analysis import force_by_status, plan_statuses

    plans = [(0.0, SimpleNamespace(source_stamp=x, status=s))
             for x, s in ((1.0, "ok"), (2.0, "rate_limited;ik:right:limit:J5;unreachable"), (3.0, "ok"))]
    t = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 2.9, 3.5, 4.0])       # the first before any plan
    ratio = np.array([1.0, 1.0, 1.3, 0.5, 0.6, 1.0, 1.1, 0.8])   # misses: 1.3, 0.5, 0.6, 0.8
    split = force_by_status(plan_statuses({"/sheet/target": plans}), t, ratio)
    assert split["no plan"] == {"share": 0.125, "within_15pct": 1.0, "of_misses": 0.0}
    assert split["unreachable"]["share"] == pytest.approx(3 / 8)
    assert split["unreachable"]["within_15pct"] == pytest.approx(1 / 3)
    assert split["unreachable"]["of_misses"] == pytest.approx(0.5)
    assert split["ok"]["of_misses"] == pytest.approx(0.5)                # 1.3 at 1.5 s and 0.8 at 4.0 s
    assert sum(v["of_misses"] for v in split.values()) == pytest.approx(1.0)
