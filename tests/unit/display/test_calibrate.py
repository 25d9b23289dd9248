"""``flexsheet calibrate display`` (flexsheet.display.calibrate): the simulated registration needs a truth
seed; the live plan's dry run prints the poses and moves nothing; ``calibrate sheet`` fits the twin's presses
and a lab's CSV alike."""

from __future__ import annotations

import os

import pytest

from flexsheet.display.calibrate import display_main


def test_display_cli_needs_a_seed(capsys):
    with pytest.raises(SystemExit):
        display_main(["--sim", "--out", "/tmp/never-written"])
    assert "--truth-seed" in capsys.readouterr().err


def test_dry_run_prints_the_poses_and_moves_nothing(capsys, tmp_path):
    assert display_main(["--live", "--dry-run", "--quick", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith("49 poses; none out of reach")
    assert not os.path.exists(tmp_path / "frames")


def test_sheet_from_the_twin_and_from_a_lab_file_give_the_same_entry(tmp_path):
    """``flexsheet calibrate sheet``: the twin's presses (truth seed 0, whose true-sheet tables ship) fit
    within the 10 % target against the true force; the readings it writes as a lab's CSV fit to the same
    entry."""
    import json

    from flexsheet.calibration.display_calib_file import load_display_calib
    from flexsheet.display.calibrate import sheet_main

    assert sheet_main(["--sim", "--truth-seed", "0", "--out", str(tmp_path / "sim")]) == 0
    doc = json.loads((tmp_path / "sim" / "sheet.json").read_text())
    assert doc["truth"]["model_error_pct"] <= 10.0 < doc["truth"]["nominal_error_pct"]
    assert len((tmp_path / "sim" / "presses.csv").read_text().splitlines()) == len(doc["readings"]) + 1
    (tmp_path / "p.csv").write_bytes((tmp_path / "sim" / "presses.csv").read_bytes())
    assert sheet_main(["--presses", str(tmp_path / "p.csv"), "--out", str(tmp_path / "lab")]) == 0
    a = load_display_calib(str(tmp_path / "sim" / "display.yaml")).sheet
    b = load_display_calib(str(tmp_path / "lab" / "display.yaml")).sheet
    assert (b.contact_width == pytest.approx(a.contact_width, rel=1e-9)
            and b.provenance.source == "lab presses p.csv")
    assert "truth" not in json.loads((tmp_path / "lab" / "sheet.json").read_text())


def test_sheet_file_errors_name_the_row_and_column(tmp_path, capsys):
    from flexsheet.display.calibrate import sheet_main

    (tmp_path / "bad.csv").write_text("stretch,u_m,v_m,depth_m,force_n\n0.02,0,0,0.002,abc\n")
    assert sheet_main(["--presses", str(tmp_path / "bad.csv"), "--out", str(tmp_path)]) == 2
    assert "row 2: force_n must be a number" in capsys.readouterr().err
    (tmp_path / "cols.csv").write_text("stretch,u,v,depth,force\n0.02,0,0,0.002,0.1\n")
    assert sheet_main(["--presses", str(tmp_path / "cols.csv"), "--out", str(tmp_path)]) == 2
    assert "missing columns ['u_m', 'v_m', 'depth_m', 'force_n']" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sheet_main(["--sim", "--out", str(tmp_path)])
    assert "--truth-seed" in capsys.readouterr().err
