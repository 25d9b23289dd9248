"""The head camera rate experiment's judging: the staleness against the guard band, the view targets, the
bag's head timing (a recorded bag, no launch)."""

import numpy as np
import pytest

from flexsheet.experiments.head_rate import TARGETS, head_timing, row
from flexsheet.runtime.bag import BagWriter
from flexsheet.runtime.codec import encode
from messages import EyePose, Header, HeadTruth
from messages import topics as T


def _summary(view_median=0.05, view_p95=0.4, eye_median=1.3):
    return {"realtime_factor": 0.7,
            "view": {"tracked": {"error_px_median": view_median, "error_px_p95": view_p95}},
            "eye": {"error_mm": {"median": eye_median, "n": 100}},
            "safety": {"keepout_violations": 0, "max_speed_near_head_mps": 0.12},
            "headline": {"rows": {"30": {"dtheta_mean_deg": 0.13}}}}


def test_staleness_is_the_fastest_head_over_a_frame_and_the_eye_age():
    timing = {"head_speed_max_mps": 0.3, "eye_age_s": 0.01}
    r60, r30 = row(60.0, _summary(), timing), row(30.0, _summary(), timing)
    assert r60["staleness_mm"] == pytest.approx(0.3 * (1 / 60 + 0.01) * 1e3)     # 8.0 mm
    assert r30["staleness_mm"] == pytest.approx(0.3 * (1 / 30 + 0.01) * 1e3)     # 13.0 mm
    assert TARGETS["staleness_mm"] == pytest.approx(10.0)
    assert r60["verdict"] == "met" and r30["verdict"] == "MISSED"


def test_a_view_error_over_its_target_misses_at_any_rate():
    slow_head = {"head_speed_max_mps": 0.01, "eye_age_s": 0.01}
    assert row(60.0, _summary(view_p95=2.5), slow_head)["verdict"] == "MISSED"
    assert row(60.0, _summary(view_median=1.2), slow_head)["verdict"] == "MISSED"
    assert row(60.0, _summary(eye_median=2.1), slow_head)["verdict"] == "MISSED"
    assert row(60.0, _summary(), slow_head)["verdict"] == "met"


def _ns(t):
    return int(round(t * 1e9))


def _head(stamp, speed):
    z = np.zeros(3)
    return HeadTruth(header=Header(stamp=stamp, frame_id="display", seq=0), position=z, rotation=np.eye(3),
                     left=z, right=z, eye=z, velocity=np.array([speed, 0.0, 0.0]), visible=True)


def _eye(stamp):
    z = np.zeros(3)
    return EyePose(header=Header(stamp=stamp, frame_id="display", seq=0), position=z, rotation=np.eye(3),
                   left=z, right=z, eye=z, velocity=z, valid=True, age=0.0, markers=14, reprojection_px=0.1)


def test_head_timing_reads_the_fastest_head_and_the_delivery_age(tmp_path):
    bag = tmp_path / "run.mcap"
    w = BagWriter(bag)
    for i, (v, age) in enumerate([(0.05, 0.010), (0.32, 0.011), (0.1, 0.012)]):
        w.write(encode(T.HEAD_TRUTH.name, _head(1000.0 + i, v)), _ns(1000.0 + i))
        w.write(encode(T.EYE_POSE.name, _eye(1000.0 + i)), _ns(1000.0 + i + age))
    w.close()
    t = head_timing(bag)
    assert t["head_speed_max_mps"] == pytest.approx(0.32)
    assert t["eye_age_s"] == pytest.approx(0.011, abs=1e-6)


def test_head_timing_without_the_topics_names_the_bag(tmp_path):
    bag = tmp_path / "empty.mcap"
    w = BagWriter(bag)
    w.write(encode(T.EYE_POSE.name, _eye(1000.0)), _ns(1000.01))
    w.close()
    with pytest.raises(ValueError, match="empty.mcap: no /world/head"):
        head_timing(bag)
