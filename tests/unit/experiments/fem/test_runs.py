"""The runs of `flexsheet experiment fem` (flexsheet/experiments/fem/runs.py): the quick run solves every
reference push in its prefetch workers, and a second run reads everything from the cache."""

import pytest

from unit.experiments.fem.conftest import _run

# the first test of the package's quick run sets it up (conftest.py: a subprocess of several minutes cold,
# timeout 1500 s in _run): pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def test_second_run_reads_the_cache(quick):
    base, s1, _ = quick
    _, _, log1 = quick
    assert "DOF, load steps" in log1                     # the cold run solved ...
    # ... every reference push in its two prefetch workers (planned_solves lists all the run reads): the run
    # itself started none
    solves = [ln for ln in log1.splitlines() if "DOF, load steps" in ln]
    assert "prefetch: " in log1 and all(ln.startswith("[solver ") for ln in solves), solves
    assert {ln.split("]")[0] for ln in solves} == {"[solver 1", "[solver 2"}
    # the pushes the tables read (the snapshots' and the snapshot-mesh
    # study's three) got their unloading sweep (stable_path) in a worker too
    sweeps = [ln for ln in log1.splitlines() if "unloading from" in ln]
    assert len(sweeps) == 3 and all(ln.startswith("[solver ") for ln in sweeps), sweeps
    s2, log = _run(base / "out2", base / "cache")
    assert "DOF, load steps" not in log and "loaded from cache" in log      # ... the second did not
    assert "unloading from" not in log
    assert s2["realtime"]["precompute_cache_hit"] is True
    assert s2["realtime"]["max_visible_error_mm_0_50"] == pytest.approx(
        s1["realtime"]["max_visible_error_mm_0_50"],
                                                                        rel=1e-9)
    assert s2["reference"]["levels"] == s1["reference"]["levels"]
