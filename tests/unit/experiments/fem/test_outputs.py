"""What the quick run writes (flexsheet/experiments/fem/outputs.py): summary.json's keys with real numbers and
the figures."""

import json
import math
import os

import pytest

# the first test of the package's quick run sets it up (conftest.py: a subprocess of several minutes cold,
# timeout 1500 s in _run): pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def test_summary_has_the_issue_keys_with_real_numbers(quick):
    base, s, _ = quick
    rt = s["realtime"]
    assert rt["method"] == "snapshots"
    assert math.isfinite(rt["update_ms"]) and 0 < rt["update_ms"] < 50
    e = rt["max_visible_error_mm_0_50"]
    assert math.isfinite(e) and 0 < e < 5.0
    assert isinstance(s["reference"]["converged"], bool)
    for name in ("convergence", "failure_map", "accuracy_speed"):
        assert os.path.getsize(base / "out" / f"{name}.png") > 5000
        with open(base / "out" / f"{name}.json") as fh:
            assert json.load(fh)
