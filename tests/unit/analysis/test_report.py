"""The run report a researcher reads (flexsheet.analysis.report): report.md parsed back from a synthetic bag.
One headline per Table I row (the felt Δθ) with the paper's figure, the target, the target's source and the
verdict; latency rows labelled modelled or measured; one delay figure; the planner's stiffness_scale; a run
cut inside a segment gets no verdict; charts with JSON that carry titles, units, targets, verdicts; the twin
the run used and both Δd conventions in summary.json."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from test_report_analysis import _write_bag

from flexsheet.analysis.report import main
from flexsheet.analysis.report_verdicts import PARTIAL
from flexsheet.analysis.table1 import PAPER_TABLE1
from flexsheet.model import geometry
from flexsheet.model.shapes import paper_cylinder
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import Fingertip, FingerTruth, Header, Heartbeat, SheetState, SheetTarget
from messages import topics as T

R = geometry.CYLINDER_RADIUS
LAG = math.radians(0.5)        # the true sheet's tangent plane trails the true finger by this angle


def _segments(script: list[tuple[str, float]]):
    """(index, mode, moving_time, t0) of each segment: approach 1 s, hold 1 s, the move, hold 1 s."""
    t0, out = 0.0, []
    for i, (mode, mt) in enumerate(script):
        out.append((i, mode, mt, t0))
        t0 += 3.0 + mt
    return out, t0


def _state(t: float, segs) -> tuple[int, str, float, str, float]:
    """(segment, mode, moving_time, phase, angle rad) at time t; the mark sweeps 60° over the moving time."""
    for i, mode, mt, t0 in segs:
        if t < t0 + 3.0 + mt:
            u = t - t0
            phase = "approach" if u < 1.0 else mode if 2.0 <= u < 2.0 + mt else "idle"
            return i, mode, mt, phase, math.radians(60.0) * min(max(u - 2.0, 0.0), mt) / mt
    i, mode, mt, _ = segs[-1]
    return i, mode, mt, "idle", math.radians(60.0)


def write_run(path, script, t_end: float | None = None, scale: float = 0.5) -> None:
    """A recorded run of the world's ``script`` ((mode, moving time s) pairs), cut at ``t_end`` (default: its
    end): truth and true sheet at 100 Hz, fingertips at 48 Hz (2 mm outside the cylinder, camera and
    triangulator stamps 6.6 and 8.4 ms after exposure), the planner's touching targets (object 50 N/m, the
    planner's heartbeat naming ``stiffness_scale``)."""
    c, w = paper_cylinder(), BagWriter(path)
    segs, total = _segments(script)
    t_end = total if t_end is None else t_end

    def put(topic, msg, t):
        w.write(encode(topic, msg), int(round(t * 1e9)))

    for k, t in enumerate(np.arange(0.0, t_end, 0.01)):
        i, mode, mt, phase, a = _state(t, segs)
        v = (np.array(c.point_at(_state(t + 1e-3, segs)[4], 0.0, R)) - np.array(c.point_at(a, 0.0, R))) / 1e-3
        put(T.FINGER_TRUTH.name,
            FingerTruth(header=Header(stamp=t, seq=k), position=np.array(c.point_at(a, 0.0, R)),
                        velocity=v, segment=i, mode=mode, moving_time=mt, phase=phase),
            t)
        b = a - LAG
        o = np.array(c.point_at(b))
        put(T.SHEET_STATE.name, SheetState(header=Header(stamp=t, seq=k), origin=o,
                                           normal=np.array([math.cos(b), 0.0, -math.sin(b)]),
                                           axis_u=np.array([0.0, 1.0, 0.0]), corners=np.zeros((4, 3)),
                                           pushed_point=o,
                                           depth=0.0, stretch=0.02, membrane=np.zeros((2, 2))), t)
    for k, t in enumerate(np.arange(0.005, t_end - 0.02, 1.0 / 48.0)):
        p = np.array(c.point_at(_state(t, segs)[4], 0.0, R + 0.002))
        put(T.FINGERTIP.name,
            Fingertip(header=Header(stamp=t + 0.0066, seq=k), position=p, covariance=np.eye(3) * 1e-8,
                      valid=True, predicted_position=p, prediction_horizon=0.025,
                      exposure_stamp=float(t),
                      frame_stamp=t + 0.0066, sent_stamp=t + 0.0084), t + 0.0084)
        st, z3 = t + 0.009, np.zeros(3)
        put(T.SHEET_TARGET.name,
            SheetTarget(header=Header(stamp=st, seq=k), contact_point=p, normal=z3, axis_u=z3,
                        axis_v=z3, sheet_origin=p, stretch=0.02, tension=100.0,
                        stiffness=50.0,
                        object_stiffness=50.0, touching=True, status="ok",
                        source_stamp=float(t)), st)
    for k, t in enumerate(np.arange(0.5, t_end, 1.0)):
        msg = "stiffness: the FEM's dF/dd" + (f"; x {scale:g} (stiffness_scale)" if scale != 1.0 else "")
        put(T.DIAGNOSTICS.name, Heartbeat(header=Header(stamp=t, seq=k), node="planner", node_type="planner",
                                          message=msg), t)
    w.close()


def _section(md: str, heading: str) -> tuple[str, list[list[str]]]:
    """The prose and the table rows (cells split at two or more spaces; header first) of a report.md
    section."""
    body = md.split(f"## {heading}\n", 1)[1].split("\n## ", 1)[0]
    prose = body.split("```")[0]
    table = body.split("```\n")[1].split("```")[0] if "```" in body else ""
    return prose, [re.split(r"\s{2,}", li.strip()) for li in table.splitlines() if li.strip()]


def _rows(table: list[list[str]]) -> dict[str, dict[str, str]]:
    head, *rows = table
    return {r[0]: dict(zip(head, r, strict=True)) for r in rows}


def _report(tmp_path, script, t_end=None, clock_sim=True, scale=0.5):
    tmp_path.mkdir(exist_ok=True)
    write_run(tmp_path / "run.mcap", script, t_end, scale)
    if clock_sim:
        (tmp_path / "sim_clock.json").write_text(json.dumps({"realtime_factor": 1.5}))
    code = main(str(tmp_path))
    return code, (tmp_path / "report.md").read_text(), json.loads((tmp_path / "summary.json").read_text())


def test_report_md_gives_one_headline_per_row_with_its_target_source_and_verdict(tmp_path):
    code, md, s = _report(tmp_path, [("stroke", 10.0)])
    assert code == 0 and md.count("Run: complete") == 1 and "PARTIAL" not in md
    prose, table = _section(md, "Table I — felt Δθ, the headline")
    row = _rows(table)["10 s"]
    felt = s["table1"]["felt"]["10"]["dtheta_mean_deg"]
    assert felt == pytest.approx(math.degrees(LAG), abs=1e-3)              # the lag built into the sheet
    assert float(row["felt Δθ mean deg"]) == pytest.approx(felt, abs=5e-4)
    assert row["paper Table I deg"] == "0.359" and float(row["target deg"]) == pytest.approx(0.1795, abs=6e-4)
    assert row["target source"] == "paper Table I ÷ 2" and "FELT_TARGET_FACTOR" in prose
    assert row["verdict"] == "MISSED" and s["headline"]["overall"] == "MISSED"     # 0.5° > 0.1795°
    assert float(row["vs target"].split()[0]) == pytest.approx(100 * (felt / 0.1795 - 1), abs=0.05)
    n, _, expected = row["n"].partition(" of ")
    assert int(n) == s["table1"]["felt"]["10"]["n"] and abs(int(expected) - 480) <= 2   # 10 s at 48 Hz
    assert [k for k in s["headline"]["rows"]] == ["10"]                   # one headline per Table I row
    # the other metrics in their own, named tables, never beside the headline
    assert [h for h in table[0] if "Δθ" in h] == ["felt Δθ mean deg"]
    assert "secondary check" in _section(md, "Table I — the paper's method (not the headline)")[0]
    assert (
        _rows(_section(md, "Table I — measured fingertip vs true sheet (not the headline)")[1])["10 s"]["n"]
            == n)


def test_latency_rows_say_modelled_on_the_sim_clock_and_measured_on_the_wall_clock(tmp_path):
    _, md, s = _report(tmp_path / "sim", [("stroke", 10.0)])
    prose, table = _section(md, "Latency per hop and end to end")
    rows = _rows(table)
    assert set(rows) == set(s["latency_ms"]["chain"]) and {r["basis"] for r in rows.values()} == {"modelled"}
    assert float(rows["exposure_to_camera_frame"]["median ms"]) == pytest.approx(6.6, abs=0.01)
    assert "declared" in prose
    _, md, _ = _report(tmp_path / "wall", [("stroke", 10.0)], clock_sim=False)
    rows = _rows(_section(md, "Latency per hop and end to end")[1])
    assert rows["camera_frame_to_fingertip"]["basis"] == "measured"
    assert rows["rendered_to_projected"]["basis"] == "modelled"                  # the projector, always


def test_one_delay_figure_from_the_chain_and_the_scaled_stiffness_says_so(tmp_path):
    _, md, s = _report(tmp_path, [("stroke", 10.0)], scale=0.5)
    prose, _ = _section(md, "Delay — exposure → sheet at its pose")
    assert prose.count("The delay:") == 1 and "not measured" in prose      # this bag has no arm chain
    assert f"a horizon of {s['delay']['exposure_to_sheet_ms']:.1f} ms" in prose  # the prediction check, named
    assert s["delay"]["exposure_to_sheet_ms"] == pytest.approx(1e3 * LAG / math.radians(6.0) + 25.0, abs=1.5)
    prose, table = _section(md, "Sheet tension and stiffness at the contacts (the planner's model)")
    row = _rows(table)["10 s"]
    assert row["stiffness_scale"] == "0.5" and row["requested k (scaled)"].startswith("50.0")
    assert row["object k (unscaled)"].startswith("100.0") and "Scaled: stiffness_scale 0.5" in prose
    assert s["compliance"]["10"]["object_stiffness_unscaled_n_per_m"]["median"] == pytest.approx(100.0)


def test_a_run_cut_inside_a_segment_is_partial_and_gets_no_verdict(tmp_path):
    code, md, s = _report(tmp_path, [("stroke", 10.0)], t_end=7.0)       # 5 s of the 10 s stroke
    assert code == 0 and "Run: PARTIAL" in md and s["run"]["partial"]
    row = _rows(_section(md, "Table I — felt Δθ, the headline")[1])["10 s"]
    assert row["verdict"] == PARTIAL and s["table1"]["verdicts"] == {"felt.10": PARTIAL}
    assert (s["headline"]["overall"] == PARTIAL
            and s["segments"]["10"]["coverage"] == pytest.approx(0.5, abs=0.01))
    n, _, expected = row["n"].partition(" of ")
    assert int(n) < 0.6 * int(expected)
    for heading in ("Table I — felt Δθ, the headline", "Latency per hop and end to end"):
        verdicts = {r["verdict"] for r in _rows(_section(md, heading)[1]).values()}
        assert verdicts <= {"-", PARTIAL}, (heading, verdicts)
    assert "Headline verdict (felt Δθ, Table I): partial — no verdict" in md and "MISSED" not in md


def test_a_complete_segment_keeps_its_verdict_when_a_later_one_is_cut(tmp_path):
    _, md, s = _report(tmp_path, [("stroke", 10.0), ("stroke", 30.0)], t_end=13.0 + 5.0)
    rows = _rows(_section(md, "Table I — felt Δθ, the headline")[1])
    assert rows["10 s"]["verdict"] == "MISSED" and rows["30 s"]["verdict"] == PARTIAL
    assert s["headline"]["overall"] == PARTIAL and "segment 30 s" in s["run"]["note"]


def test_charts_carry_title_units_target_and_verdict(tmp_path):
    _report(tmp_path, [("stroke", 10.0)])
    t1 = json.loads((tmp_path / "table1.json").read_text())
    assert t1["rows"]["10"]["target_deg"] == pytest.approx(PAPER_TABLE1["10"]["dtheta_mean_deg"] / 2)
    assert (t1["rows"]["10"]["verdict"] == "MISSED" and t1["units"] == {"dtheta": "deg", "dd": "mm"}
            and t1["title"])
    felt = json.loads((tmp_path / "felt.json").read_text())
    assert felt["unit"] == "deg" and felt["verdicts"] == {"10": "MISSED"}
    assert felt["target_source"]["10"] == "paper Table I ÷ 2"
    lat = json.loads((tmp_path / "latency.json").read_text())
    assert lat["unit"] == "ms" and lat["rows"]["exposure_to_camera_frame"]["basis"] == "modelled"
    for f in ("table1.png", "felt.png", "latency.png"):
        assert (tmp_path / f).stat().st_size > 5000, f
        assert f in (tmp_path / "report.md").read_text()


def test_report_records_the_twin_and_both_dd_conventions(tmp_path):
    """summary.json has Table I's Δθ headline with Δd on R and in the paper's 2R convention, and the twin the
    run used (a launch file's top-level ``twin:``, else the world node's ``twin`` param)."""

    from flexsheet.analysis.report import main, twin_settings
    from flexsheet.analysis.table1 import paper_dd_ratio
    from flexsheet.runtime.launch import load_launch

    _write_bag(tmp_path / "run.mcap")
    lf_path = tmp_path / "l.yaml"
    lf_path.write_text("name: t\nnodes:\n  world:\n    type: world\n    params: {twin: {realism: ideal, "
                       "truth_seed: 2}}\n")
    assert main(str(tmp_path), load_launch(lf_path)) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["twin"] == {"realism": "ideal", "truth_seed": 2, "source": "world node params"}
    row = s["10"]
    assert row["dtheta_mean_deg"] == pytest.approx(math.degrees(LAG), abs=1e-4)
    assert row["dd_2r_mean_mm"] == pytest.approx(2e3 * R * LAG, abs=1e-4)           # the paper's convention
    assert row["dd_mean_mm"] == pytest.approx(2e3 * R * math.sin(LAG / 2), abs=1e-4)  # ours: the chord on R
    assert paper_dd_ratio("10") == pytest.approx(2e3 * R, rel=0.01)  # why: the paper's Δd/Δθ = 2R
    assert "2R" in s["dd_convention"] and "2R" in (tmp_path / "report.md").read_text()
    top_path = tmp_path / "top.yaml"
    top_path.write_text("name: t\ntwin: {realism: realistic, truth_seed: 5, registration: false}\n"
                        "nodes:\n  world:\n    type: world\n    params: {twin: {realism: ideal, truth_seed: "
                        "2}}\n")
    assert twin_settings(load_launch(top_path)) == {"realism": "realistic", "truth_seed": 5,
                                                    "source": "launch file twin section"}
    assert twin_settings(None)["source"].startswith("world node defaults")


def test_an_earlier_runs_bags_in_a_reused_folder_are_left_out(tmp_path):
    """The launch passes its start: the report reads only the bags written since (a respawned recorder's parts
    all are), not an earlier run's in the same --out folder; without a start, every bag, oldest first."""
    import os

    from flexsheet.analysis.report import run_bags

    old, part0, part1, replay = (tmp_path / n
                                 for n in ("sim.mcap", "sim.1.mcap", "sim.2.mcap", "replay.mcap"))
    for k, p in enumerate((old, part0, part1, replay)):
        p.write_bytes(b"")
        os.utime(p, (1000.0 + 100 * k, 1000.0 + 100 * k))
    assert run_bags(tmp_path) == [old, part0, part1]
    assert run_bags(tmp_path, since=1050.0) == [part0, part1]
    assert run_bags(tmp_path, since=5000.0) == []


def test_the_report_judges_the_planners_sheet_model_against_the_truth_of_the_run(monkeypatch):
    """``compliance.model_error_pct``: the identified entry of the run's seed is within 5 % over the working
    strains; the same run judged with the nominal string band's entry reads far worse; a launch that names its
    own display_calib (a lab) gets no figure."""
    from dataclasses import replace

    import flexsheet.twin.registration as reg
    from flexsheet.analysis.report import sheet_model_error
    from flexsheet.calibration.display_calib_file import load_display_calib

    # seed 0's entry (flexsheet calibrate sheet --sim)
    path = str(Path(__file__).resolve().parents[3] / "docs/figures/calibration/sheet/display.yaml")
    monkeypatch.setattr(reg, "sim_display_calib_cached", lambda seed, realism: path)
    s = {"twin": {"truth_seed": 0, "realism": "realistic"}, "compliance": {"n": 1}}
    sheet_model_error(s, None)
    assert s["compliance"]["model_error_pct"] <= 5.0 and s["compliance"]["model_error"]["n"] > 400
    entry = load_display_calib(path).sheet
    nominal = replace(entry, contact_width=0.02, contact_growth=0.0, own_stiffness=0.0, own_growth=0.0,
                      stretching=0.0, strain_offset=0.0, position_u=0.0, position_v=0.0)
    monkeypatch.setattr(reg, "working_model_error",
                        lambda truth, sheet, f=reg.working_model_error: f(truth, nominal))
    s2 = {"twin": {"truth_seed": 0, "realism": "realistic"}, "compliance": {"n": 1}}
    sheet_model_error(s2, None)
    assert s2["compliance"]["model_error_pct"] > 30.0

    class Lab:
        def section(self, name):
            return "/lab/display.yaml" if name == "display_calib" else None
    s3 = {"twin": {"truth_seed": 0, "realism": "realistic"}, "compliance": {"n": 1}}
    sheet_model_error(s3, Lab())
    assert "model_error_pct" not in s3["compliance"]


def test_the_report_judges_the_sheet_model_where_the_run_touched_the_sheet(monkeypatch):
    """``compliance.model_error_contacts``: the identified entry against the truth at the run's own contacts,
    weighted by their samples; a contact's weight moves the figure toward that contact's own error."""
    import flexsheet.twin.registration as reg
    from flexsheet.analysis.report import sheet_model_error
    from flexsheet.calibration.display_calib_file import load_display_calib
    from flexsheet.twin.truth import TwinTruth

    path = str(Path(__file__).resolve().parents[3] / "docs/figures/calibration/sheet/display.yaml")
    monkeypatch.setattr(reg, "sim_display_calib_cached", lambda seed, realism: path)
    uv = [[0.0, 0.0], [0.054, 0.0]]
    s = {"twin": {"truth_seed": 0, "realism": "realistic"},
         "compliance": {"n": 1, "contacts_on_sheet": {"uv_m": uv, "n": [1, 1]}}}
    sheet_model_error(s, None)
    mc = s["compliance"]["model_error_contacts"]
    assert mc["contacts"] == 2 and 0.0 < mc["median_pct"] <= mc["p90_pct"] <= mc["max_pct"] and mc[
        "target_pct"] == 5.0
    truth, sheet = TwinTruth.draw(0, "realistic"), load_display_calib(path).sheet
    centre = reg.contacts_model_error(truth, sheet, uv[:1])
    off = reg.contacts_model_error(truth, sheet, uv[1:])
    heavy = reg.contacts_model_error(truth, sheet, uv, [1, 50])
    assert abs(heavy["median_pct"] - off["median_pct"]) < abs(heavy["median_pct"] - centre["median_pct"])
    with pytest.raises(ValueError, match="weights"):
        reg.contacts_model_error(truth, sheet, uv, [1, 2, 3])



def test_the_module_command_teaches_with_help_and_says_when_a_folder_has_no_bag(tmp_path, capsys):
    import pytest

    from flexsheet.analysis.report import cli

    with pytest.raises(SystemExit) as e:
        cli(["--help"])
    assert e.value.code == 0
    assert "example: python -m flexsheet.analysis.report out/sim" in capsys.readouterr().out
    assert cli([str(tmp_path)]) == 1
    assert f"[report] no bag in {tmp_path}" in capsys.readouterr().out


def test_a_report_again_without_the_launch_file_keeps_the_scene_the_run_reported(tmp_path):
    from flexsheet.analysis.report import scene_settings

    scene_file = Path(__file__).resolve().parents[3] / "launch" / "scenes" / "sphere.yaml"
    (tmp_path / "summary.json").write_text(json.dumps({"scene": {"name": "sphere", "file": str(scene_file)}}))
    sc, entry = scene_settings(None, str(tmp_path))
    assert sc.name == "sphere" and entry["file"] == str(scene_file.resolve())
    assert "earlier summary.json" in entry["source"]
    sc, entry = scene_settings(None, str(tmp_path / "nothing"))          # no summary there: the cylinder
    assert entry["file"] is None and "no earlier summary.json" in entry["source"]
