"""Table I from a recorded bag (flexsheet.experiments.report): the typed truth picks the stroking segments and
the row matches the errors built into synthetic data (the sheet lagging the finger by a known angle)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexsheet.experiments.report import analyse
from flexsheet.experiments.table1 import PAPER_TABLE1
from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder
from flexsheet.runtime.bag import BagWriter
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
        put(T.FINGER_TRUTH.name, FingerTruth(header=Header(stamp=t, seq=k), position=np.array(c.point_at(a, 0.0, R)),
                                             velocity=np.zeros(3), segment=seg, mode=mode, moving_time=mt,
                                             phase=phase), t)
        b = a - LAG
        n = np.array([math.cos(b), 0.0, -math.sin(b)])     # point_at: positive angles go down (−z)
        o = np.array(c.point_at(b))
        put(T.SHEET_STATE.name, SheetState(header=Header(stamp=t, seq=k), origin=o, normal=n,
                                           axis_u=np.array([0.0, 1.0, 0.0]), corners=np.zeros((4, 3)),
                                           pushed_point=o, depth=0.0, stretch=0.02, membrane=np.zeros((2, 2))), t)
    for k, t in enumerate(np.arange(0.005, t_end - 0.02, 1.0 / 48.0)):
        valid = k != 60
        p = np.array(c.point_at(_angle(t), 0.0, R + 0.002))
        put(T.FINGERTIP.name, Fingertip(header=Header(stamp=t, seq=k), position=p if valid else np.zeros(3),
                                        covariance=np.eye(3) * 1e-8, valid=valid, predicted_position=np.zeros(3),
                                        exposure_stamp=float(t)), t + 0.01)
        n_stroke += valid and 1.0 <= t < 2.5
    w.close()
    return n_stroke


def test_report_table1_from_bag_uses_typed_truth_and_the_one_metric(tmp_path):
    n_stroke = _write_bag(tmp_path / "run.mcap")
    s = analyse(tmp_path / "run.mcap")
    assert s["counts"][T.FINGERTIP.name] > 100 and s["fingertip_invalid"] == 1
    row = s["10"]
    assert row["n"] == n_stroke                                   # only the 'stroke' phase of the 10 s segment
    # the sheet lags by LAG around the axis: Δθ = LAG, Δd = chord 2R sin(LAG/2) (Fig. 9 on the surface)
    assert row["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-4)
    assert row["dd_mean_mm"] == pytest.approx(2e3 * R * math.sin(LAG / 2), abs=1e-4)
    assert row["dd_std_mm"] < 1e-4 and row["gap_mean_mm"] < 1e-4     # 100 Hz sheet: interpolation only
    assert row["paper"] == PAPER_TABLE1["10"]
    push = s["stroke_push_4"]                                     # the second segment, keyed by its mode
    assert push["n"] >= 10 and "paper" not in push
    assert set(s["latency_ms"]) >= {"fingertip_to_sheet_target", "camera_frame_to_arm_command"}


def test_report_records_the_twin_and_both_dd_conventions(tmp_path):
    """summary.json has Table I's Δθ headline with Δd on R and in the paper's 2R convention, and the twin the run
    used (a launch file's top-level ``twin:``, else the world node's ``twin`` param)."""

    from flexsheet.experiments.report import main, twin_settings
    from flexsheet.experiments.table1 import paper_dd_ratio
    from flexsheet.runtime.launch import load_launch

    _write_bag(tmp_path / "run.mcap")
    lf_path = tmp_path / "l.yaml"
    lf_path.write_text("name: t\nnodes:\n  world:\n    type: world\n    params: {twin: {realism: ideal, truth_seed: 2}}\n")
    assert main(str(tmp_path), load_launch(lf_path)) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["twin"] == {"realism": "ideal", "truth_seed": 2, "source": "world node params"}
    row = s["10"]
    assert row["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-4)
    assert row["dd_2r_mean_mm"] == pytest.approx(2e3 * R * LAG, abs=1e-4)           # the paper's convention
    assert row["dd_mean_mm"] == pytest.approx(2e3 * R * math.sin(LAG / 2), abs=1e-4)  # ours: the chord on R
    assert paper_dd_ratio("10") == pytest.approx(2e3 * R, rel=0.01)                 # why: the paper's Δd/Δθ = 2R
    assert "2R" in s["dd_convention"] and "2R" in (tmp_path / "report.md").read_text()
    top_path = tmp_path / "top.yaml"
    top_path.write_text("name: t\ntwin: {realism: realistic, truth_seed: 5, registration: false}\n"
                        "nodes:\n  world:\n    type: world\n    params: {twin: {realism: ideal, truth_seed: 2}}\n")
    assert twin_settings(load_launch(top_path)) == {"realism": "realistic", "truth_seed": 5,
                                                    "source": "launch file twin section"}
    assert twin_settings(None)["source"].startswith("world node defaults")


def test_report_text_leaves_dd_2r_blank_on_a_shape_with_no_radius():
    """The rounded box and the organ have no radius R, so their rows carry no Δd 2R: the text table prints "-"
    there (it printed "nan", which reads as a failed measurement), and the number where there is one."""
    from flexsheet.experiments.report import _format

    row = {"dtheta_mean_deg": 0.5, "dtheta_std_deg": 0.25, "dd_mean_mm": 1.25, "n": 120}
    text = _format({"10": row, "30": {**row, "dd_2r_mean_mm": 0.875}, "latency_ms": {}})
    line10 = next(li for li in text.splitlines() if li.startswith("10 s"))
    line30 = next(li for li in text.splitlines() if li.startswith("30 s"))
    assert line10.split()[2:6] == ["0.500", "0.250", "-", "1.250"], line10
    assert line30.split()[2:6] == ["0.500", "0.250", "0.875", "1.250"], line30
