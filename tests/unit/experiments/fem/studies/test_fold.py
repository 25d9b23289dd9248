"""The fold study (flexsheet/experiments/fem/studies/fold.py) on the quick run's cache: no fold on the coarse
meshes, and the tip-refined sequence."""

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


def test_fold_study_reads_the_levels_from_the_cache_and_finds_no_fold_on_the_coarse_meshes(quick):
    """--fold-study checks the reference's own surface for folds (it has no self-contact): it reads the quick
    run's cached levels (solving only its tip-refined sequence), and the coarse meshes' visible surface stays
    smooth (w ≈ ½, nothing inside the body) to 50 mm, while the material over the fingertip (footprint
    included) is kinked at the apex (w > ½) and stretched several times over; its differences to the finest
    level are the convergence study's."""
    base, _, _ = quick
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf",
                        "--fold-study", "--out",
                        str(base / "fold"), "--cache-dir", str(base / "cache"), "--jobs", "2"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    solved = [ln for ln in r.stdout.splitlines() if "DOF, load steps" in ln]
    assert len(solved) == 2 and all(",tip=" in ln for ln in solved), solved     # the tip sequence only
    assert "fold study done" in r.stdout
    with open(base / "fold" / "fold_study.json") as fh:
        fs = json.load(fh)
    assert os.path.getsize(base / "fold" / "fold_study.png") > 5000
    assert fs["depths_mm"] == pytest.approx([5.0 * k for k in range(1, 11)])
    assert [lv["h_fine_mm"] for lv in fs["levels"]] == pytest.approx([12.0, 9.0])
    for lv in fs["levels"]:
        assert max(lv["n_penetrating"]) == 0 and max(lv["max_penetration_mm"]) == 0.0
        assert 0.49 < max(lv["max_winding"]) < 0.6
        fp = lv["with_footprint"]
        assert max(fp["n_penetrating"]) == 0 and fp["max_winding"][-1] > max(lv["max_winding"])
        assert fp["max_stretch_ratio"][-1] > 2.0 and lv["min_stretch_ratio"][-1] < lv["min_stretch_ratio"][
            0] < 1.0
        assert lv["max_principal_strain"][-1] > lv["max_principal_strain"][0] > 0
    assert (fs["fold_free_to_mm"] == 50.0
            and fs["first_penetration_mm_by_h_fine_mm"] == {"12.0": None, "9.0": None})
    tip = fs["tip_sequence"]
    assert [t["h_fine_mm"] for t in tip["levels"]] == pytest.approx([12.0, 9.0])
    assert [t["tip_h_mm"] for t in tip["levels"]] == pytest.approx([5.0, 4.0])
    assert tip["converged"] is False and "tip_check" not in tip              # two levels cannot converge
    assert max(tip["levels"][-1]["difference_to_finest_mm"]) == 0.0
    assert tip["last_refinement_change_mm"] == pytest.approx(max(tip["levels"][0]["difference_to_finest_mm"]))
    for t, lv in zip(tip["levels"], fs["levels"], strict=True):  # the tip adds elements at the push point
        assert t["dofs"] > lv["dofs"] and t["newton_converged"]
    # the finer apex stretches more: the strain at 50 mm on the tip level exceeds the plain level's
    assert tip["levels"][-1]["max_principal_strain"][-1] > fs["levels"][-1]["max_principal_strain"][-1]
    # azimuth-0 snapshot tables on the next-to-finest plain and tip levels, judged against
    # the finest tip level: the tip-refined table is the closer one at the deep end
    plain, tipped = tip["snapshots"]["tables"]
    assert plain["tip_h_mm"] == 0.0 and tipped["tip_h_mm"] == pytest.approx(5.0) and len(
        tipped["error_mm"]) == 10
    assert tipped["max_visible_error_mm"] < plain["max_visible_error_mm"]
    assert max(tipped["error_mm"][-3:]) < min(plain["error_mm"][-3:])
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    assert fs["levels"][0]["difference_to_finest_mm"] == pytest.approx(
        conv["levels"][0]["error_vs_finest_mm"],
                                                                       rel=1e-9)
