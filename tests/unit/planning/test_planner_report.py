"""Table I from a recorded bag (flexsheet.experiments.report): the typed truth picks the stroking segments and
the row matches the errors built into synthetic data (the sheet lagging the finger by a known angle)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flexsheet.experiments.report_analysis import analyse
from flexsheet.experiments.table1 import PAPER_TABLE1
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
    assert set(s["latency_ms"]["chain"]) >= {"fingertip_to_sheet_target", "exposure_to_arm_command",
                                             "exposure_to_projected"}
    # felt: the true finger against the true sheet, here the same lag; the 3-D angle equals the
    # section angle (the sheet's normal lies in the section); no joint readback in this bag: no paper row
    felt = s["table1"]["felt"]["10"]
    assert felt["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-3) and felt["n"] == n_stroke
    assert felt["angle3d_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-3)
    assert s["table1"]["paper"] == {}
    assert s["table1"]["verdicts"] == {"felt.10": "MISSED"}                 # 0.5° against 0.359 / 2
    dc = s["table1"]["decomposition"]["10"]          # no tremor, camera error only along the normal: the lag is all
    assert dc["tremor"] < 0.01 and dc["camera"] < 0.01 and dc["slow_finger"] == pytest.approx(math.degrees(LAG), abs=0.01)
    assert s["table1"]["targets"]["felt"]["10"] == pytest.approx(PAPER_TABLE1["10"]["dtheta_mean_deg"] / 2)
    # the sheet trails the finger by LAG at OMEGA: LAG / OMEGA = 83.3 ms, found by the lag fit (1 ms grid)
    assert s["delay"]["segment"] == "10" and s["delay"]["horizon_ms"] == 0.0
    assert s["delay"]["exposure_to_sheet_ms"] == pytest.approx(1e3 * LAG / OMEGA, abs=1.0)
    assert s["delay"]["angle_at_best_deg"] < 0.03                         # against 0.5 deg unaligned


def test_graph_stroke_judges_every_row_by_its_worst_seed():
    """flexsheet experiment stroke's aggregate: a row is met only when every seed meets it; a seed missing a row
    leaves that row unmeasured (MISSED)."""
    from flexsheet.experiments.stroke import aggregate

    def run(felt10, felt30, paper10):
        return {"table1": {"felt": {"10": {"dtheta_mean_deg": felt10, "n": 400}, "30": {"dtheta_mean_deg": felt30}},
                           "paper": {"10": {"dtheta_mean_deg": paper10}}},
                "delay": {"exposure_to_sheet_ms": 24.0}}

    a = aggregate({0: run(0.10, 0.10, 0.05), 1: run(0.17, 0.12, 0.08), 2: run(0.15, 0.05, 0.02)})
    assert a["table1"]["felt"]["10"]["dtheta_mean_deg"] == 0.17 and a["table1"]["felt"]["30"]["dtheta_mean_deg"] == 0.12
    assert a["verdicts"]["felt.10"] == "met"                       # 0.17 <= 0.1795
    assert a["verdicts"]["felt.30"] == "MISSED"                    # seed 1: 0.12 > 0.1125
    assert a["verdicts"]["paper.10"] == "met" and a["verdicts"]["paper.30"].startswith("MISSED (not measured")
    assert a["table1"]["felt"]["10"]["per_seed"][1]["n"] == 400 and set(a["delay"]) == {0, 1, 2}


def test_latency_chain_comes_from_the_nodes_stamps_and_adds_up():
    """One fingertip sample through both chains, with made-up stamps (s): every hop is a difference of stamps the
    nodes set (the recorder's arrival times, here absurd on purpose, are never used); the ends are the sums;
    the sheet is at its pose at the later of the two arms' first readbacks within 0.1 mm and 0.05 deg."""
    from types import SimpleNamespace as NS

    from flexsheet.experiments.report_timing import latency_hops
    from flexsheet.model.timing import LAB

    e = 100.0
    goal = np.eye(4)
    near = np.eye(4)
    near[:3, 3] = [5e-5, 0.0, 0.0]                     # 0.05 mm off: at the pose
    far = np.eye(4)
    far[:3, 3] = [2e-4, 0.0, 0.0]                      # 0.2 mm off: not yet
    tip = NS(exposure_stamp=e, frame_stamp=e + 0.006, sent_stamp=e + 0.007)
    d = {"/fingertip": [(999.0, tip)],
         "/sheet/target": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0075)))],
         "/object/deformation": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0074)))],
         "/render/stereo": [(0.0, NS(source_stamp=e, header=NS(stamp=e + 0.0114)))]}
    for arm, t_write, t_at in (("left", e + 0.0080, e + 0.0200), ("right", e + 0.0078, e + 0.0271)):
        d[f"/arm/{arm}/target"] = [(0.0, NS(source_stamp=e, pose=goal))]
        d[f"/arm/{arm}/joint_state"] = [
            (0.0, NS(target_stamp=e, write_stamp=t_write, pose=far, header=NS(stamp=t_write + 0.001))),
            (0.0, NS(target_stamp=e, write_stamp=t_write, pose=near, header=NS(stamp=t_at)))]
    out = latency_hops(d)
    c = {k: v["median"] for k, v in out["chain"].items()}
    assert c["exposure_to_camera_frame"] == pytest.approx(6.0) and c["camera_frame_to_fingertip"] == pytest.approx(1.0)
    assert c["fingertip_to_sheet_target"] == pytest.approx(0.5)
    assert c["sheet_target_to_arm_command"] == pytest.approx(0.3)          # the earlier of the two arms' writes
    assert c["exposure_to_arm_command"] == pytest.approx(7.8)
    assert c["arm_command_to_sheet_at_pose"] == pytest.approx(27.1 - 7.8)   # the later arm at its pose
    assert c["exposure_to_sheet_at_pose"] == pytest.approx(27.1) and out["sheet_at_pose_reached"] == 1.0
    projected = (LAB.projected_at(e + 0.0114) - e) * 1e3
    assert c["exposure_to_projected"] == pytest.approx(projected)
    assert c["exposure_to_projected"] == pytest.approx(sum(c[h] for h in (
        "exposure_to_camera_frame", "camera_frame_to_fingertip", "fingertip_to_deformation",
        "deformation_to_rendered_frame", "rendered_to_projected")))
    assert 11.4 + 0.0 < projected <= 11.4 + 1e3 / LAB.projector_refresh_hz + LAB.projector_input_latency_s * 1e3


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
    from flexsheet.experiments.report_text import format_text as _format

    row = {"dtheta_mean_deg": 0.5, "dtheta_std_deg": 0.25, "dd_mean_mm": 1.25, "n": 120}
    text = _format({"10": row, "30": {**row, "dd_2r_mean_mm": 0.875}, "latency_ms": {}})
    line10 = next(li for li in text.splitlines() if li.startswith("10 s"))
    line30 = next(li for li in text.splitlines() if li.startswith("30 s"))
    assert line10.split()[2:6] == ["0.500", "0.250", "-", "1.250"], line10
    assert line30.split()[2:6] == ["0.500", "0.250", "0.875", "1.250"], line30


def test_graph_stability_sets_one_error_at_a_time_and_finds_where_it_breaks(tmp_path):
    """flexsheet experiment stability --graph: each error reaches the graph as one launch override (camera noise,
    the camera link's delay in s, lost frames); the breaking points come from the felt rows; the chart says them."""
    import json

    from flexsheet.experiments.stability import GRAPH_SWEEPS, breaking_point, graph_chart, graph_sets

    assert graph_sets("noise_scale", 8.0, tmp_path, 0) == ["camera.noise_scale=8"]
    assert graph_sets("link_delay_ms", 50.0, tmp_path, 0) == ["camera.link_delay_s=0.05"]
    assert graph_sets("drop_rate", 0.6, tmp_path, 0) == ["camera.drop_rate=0.6"]
    assert graph_sets("base_error", 0.0, tmp_path, 0) == []                 # the twin's own registration
    with pytest.raises(ValueError, match="unknown error 'x'"):
        graph_sets("x", 1.0, tmp_path, 0)
    assert all(v[1][0] == (1.0 if k == "noise_scale" else 0.0) for k, v in GRAPH_SWEEPS.items())   # baselines first
    x, y = [0.0, 25.0, 50.0, 100.0], [0.11, 0.15, 0.30, 0.50]
    assert breaking_point(x, y, 0.359) == pytest.approx(50.0 + 50.0 * (0.359 - 0.30) / 0.20)
    assert breaking_point(x, y, 0.9) is None
    res = {"title": "t", "paper_dtheta_deg": 0.359, "target_dtheta_deg": 0.18, "errors": {
        "link_delay_ms": {"label": "ms", "rows": [{"value": a, "dtheta_mean_deg": b} for a, b in zip(x, y, strict=True)],
                          "breaks_paper_at": breaking_point(x, y, 0.359), "breaks_target_at": breaking_point(x, y, 0.18)}}}
    graph_chart(res, tmp_path / "s.png")
    assert (tmp_path / "s.png").stat().st_size > 5000 and json.dumps(res)


def test_the_presentable_range_comes_from_the_first_limit_and_the_mapping_keeps_ratios(tmp_path):
    """flexsheet experiment compliance: the range ends at the stretch where the clamp pulls the arm's 9.81 N (the
    strain limit, 30 %, comes later); one scale maps the scene's largest request to the range's top, so the ratio
    of two requests inside the range is the ratio presented; a request below the floor is presented at the floor
    (no contrast); the tumour's contrast is judged against the 23 % Weber fraction."""
    from flexsheet.experiments.compliance import presentable_range, run
    from flexsheet.model.tension import SheetMaterial, clamp_force, stiffness

    r = presentable_range(9.81)
    mat = SheetMaterial()
    assert r["limited_by"] == "arm_pull" and clamp_force(r["max_stretch"], mat) == pytest.approx(9.81, rel=1e-6)
    assert r["k_max_n_per_m"] == pytest.approx(stiffness(r["max_stretch"], mat))
    assert r["limits"]["strain"]["stretch"] == 0.30 and r["limits"]["strain"]["k_n_per_m"] > r["k_max_n_per_m"]
    assert presentable_range(1e4)["limited_by"] == "strain"
    res = run(tmp_path, "launch/scenes/organ.yaml")
    s, rng = res["scale"], res["range"]
    assert s * res["requested_along_stroke"]["k_max_n_per_m"] == pytest.approx(rng["k_max_n_per_m"])
    t = res["push"]["tumour"]
    k, kp = np.asarray(t["k_requested_n_per_m"]), np.asarray(t["k_presented_n_per_m"])
    inside = s * k > rng["k_min_n_per_m"]
    assert inside.any() and np.allclose(kp[inside], s * k[inside])          # ratios kept inside the range
    assert np.all(kp[~inside] == rng["k_min_n_per_m"])                       # the floor below it
    for c in res["tumour_contrast"]:
        assert c["felt"] == (c["presented"] >= 0.23) and c["presented"] <= c["asked"] + 1e-12
    assert (tmp_path / "compliance.png").stat().st_size > 5000


def test_a_refused_value_is_where_the_error_breaks_at_the_latest():
    from flexsheet.experiments.stability import breaking_point

    assert breaking_point([0.0, 4.0, 8.0, 16.0], [0.11, 0.15, 0.28, float("inf")], 0.359) == 16.0
    assert breaking_point([0.0, 4.0, 8.0, 16.0], [0.11, 0.40, 0.28, float("nan")], 0.359) == pytest.approx(
        0.0 + 4.0 * (0.359 - 0.11) / (0.40 - 0.11))
