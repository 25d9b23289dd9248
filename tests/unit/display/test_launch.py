"""The display's launch extension before a launch (flexsheet.display.launch, before_launch): ``--check`` never
runs the twin's registration."""

import json
from pathlib import Path

import pytest

from flexsheet.calibration.procedures import FULL


def test_launch_check_with_a_stale_twin_registration_notes_it_and_runs_nothing(tmp_path, monkeypatch):
    """``flexsheet launch … --check`` must not run the twin's registration: a cache written by older
    procedures (another summary version) reads as absent — a note — like an empty one; a current one is used
    as is."""
    from flexsheet.display.launch import before_launch
    from flexsheet.runtime.launch import TOPLEVEL_ENV, load_launch
    from flexsheet.runtime.testing import console_lines
    from flexsheet.twin import registration as reg

    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))
    monkeypatch.setattr(reg, "run_display_sim", lambda *a,
                        **k: pytest.fail("the registration ran on --check"))
    d = tmp_path / "display" / "realistic-77"
    d.mkdir(parents=True)
    (d / "display.yaml").write_text("{}\n")
    key = reg._cache_key(77, "realistic", FULL)
    (d / "summary.json").write_text(json.dumps({**key, "version": reg.SUMMARY_VERSION - 1}))
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"twin": {"truth_seed": 77, "realism": "realistic"}}))
    lf = load_launch(Path(__file__).resolve().parents[3] / "launch" / "sim.yaml")
    with console_lines() as said:
        assert before_launch(lf, check_only=True) == {}
    assert said == [f"{lf.path}: the twin registration (truth seed 77) runs at start and writes "
                    f"{d / 'display.yaml'}"]
    (d / "summary.json").write_text(json.dumps(key))
    assert before_launch(lf, check_only=True) == {"display_calib": str(d / "display.yaml")}
