"""``flexsheet calibrate display`` (flexsheet.display.calibrate): the simulated registration needs a truth seed;
the live plan's dry run prints the poses and moves nothing."""

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
