"""The material study (flexsheet/experiments/fem/studies/material.py) on the quick run's cache: Gent stiffens
the deep push only and is judged against its own finest level."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = str(Path(__file__).resolve().parents[5])

# the first test of the package's quick run sets it up (conftest.py: a subprocess of several minutes cold,
# timeout 1500 s in _run): pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def test_material_study_gent_stiffens_the_deep_push_only_and_is_judged_against_its_own_finest_level(quick):
    """--material-study: the quick run's neo-Hookean levels come from its cache, only the Gent solid's (Jm
    97.2, natural rubber) two levels and its table's stable branch are solved. Physics whatever the mesh: Gent
    is the neo-Hookean solid at small strain (the two finest solutions within 0.05 mm at 5 mm) and stiffer
    where the chains stretch (more force, less strain at 50 mm on every level, the distance between the
    materials growing with depth), its strain stays below its own limiting extensibility; the snapshots are
    judged against the finer level, never the one they were sampled from."""
    base, _, _ = quick
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf",
                        "--material-study",
                        "--out", str(base / "material"), "--cache-dir", str(base / "cache"), "--jobs", "2"],
                       cwd=ROOT,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    solved = [ln for ln in r.stdout.splitlines() if "DOF, load steps" in ln]
    assert len(solved) == 2, solved                                      # the Gent levels only
    assert r.stdout.count("unloading from 50 mm") == 1                   # and the Gent table's stable branch
    with open(base / "material" / "material_study.json") as fh:
        ms = json.load(fh)
    assert os.path.getsize(base / "material" / "material_study.png") > 5000
    nh, gent = ms["materials"]
    assert nh["name"] == "neo-Hookean" and nh["Jm"] is None and gent["Jm"] == pytest.approx(97.2)
    for a, b in zip(nh["convergence"]["levels"], gent["convergence"]["levels"], strict=True):
        assert a["dofs"] == b["dofs"] and b["newton_converged"] and max(b["inverted_qp"]) == 0
        assert b["force_N"][-1] > 1.02 * a["force_N"][-1]                 # stiffer at 50 mm
        assert b["force_N"][0] == pytest.approx(a["force_N"][0], rel=0.02)  # the same solid at 5 mm
        assert b["max_strain"][-1] < a["max_strain"][-1]
        assert max(b["max_strain"]) < (97.2 + 2.0) / 2.0                 # I1 - 3 < Jm bounds every stretch
    d = ms["difference_between_materials_mm"]
    assert len(d) == 10 and d[0] < 0.05 and d[-1] > 0.3 and d[-1] > 5 * d[1]
    for row, conv in ((nh, nh["convergence"]), (gent, gent["convergence"])):
        sn = row["snapshots_azimuth0"]
        assert sn["mesh"]["h_fine"] == pytest.approx(0.012) and len(sn["error_mm"]) == 10
        assert min(sn["error_mm"]) > 0  # judged against the 9 mm level, not itself
        assert sn["max_visible_error_mm"] == pytest.approx(max(sn["error_mm"]))
        # at 50 mm, a snapshot depth, the table is its own material's 12 mm solve: its error is that level's
        # distance to the 9 mm level (a table of the other material would be ~0.8 mm off it)
        assert sn["error_mm"][-1] == pytest.approx(conv["levels"][0]["error_vs_finest_mm"][-1], abs=0.15)
        assert conv["converged"] is False                                 # two levels cannot converge
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    assert nh["convergence"]["levels"][0]["error_vs_finest_mm"] == pytest.approx(
        conv["levels"][0]["error_vs_finest_mm"], rel=1e-9)
