"""The two experiments that launch the graph, in their quick modes: ``flexsheet experiment determinism --quick``
(two simulated-clock runs, byte-identical on every recorded topic) and ``flexsheet experiment latency_load
--quick`` (one wall-clock run with no busy core: the loop's two chain ends measured from the bag)."""

from __future__ import annotations

import json
import math

import pytest

pytestmark = pytest.mark.slow


def test_determinism_quick_two_runs_write_the_same_bytes(tmp_path):
    from flexsheet.experiments.determinism import QUICK_S, main

    assert main(["--quick", "--out", str(tmp_path)]) == 0
    d = json.loads((tmp_path / "determinism.json").read_text())
    assert d["duration_s"] == QUICK_S and d["identical"] is True and d["verdicts"]["byte_identical"] == "met"
    assert len(d["topics"]) >= 8 and all(d["topics"].values())
    assert {"/fingertip", "/sheet/target", "/render/stereo"} <= set(d["topics"])
    for run in d["runs"]:
        assert run["hashes"]["/fingertip"]["messages"] > 100          # the finger camera ran for seconds
    # the modelled lab chain is a property of the simulated clock: the same in both runs, within its budget
    ch = d["runs"][0]["chain_ms"]
    assert d["runs"][1]["chain_ms"] == ch
    assert 0.0 < ch["exposure_to_arm_command"]["median"] <= 15.0
    assert (tmp_path / "determinism.png").stat().st_size > 5_000


def test_latency_load_quick_measures_both_chain_ends(tmp_path):
    from flexsheet.experiments.latency_load import HOPS, QUICK_SCRIPT, main

    assert main(["--quick", "--out", str(tmp_path)]) == 0
    d = json.loads((tmp_path / "latency_load.json").read_text())
    assert d["script"] == QUICK_SCRIPT and [r["busy_cores"] for r in d["runs"]] == [0]
    lat = d["runs"][0]["latency_ms"]
    for hop in HOPS:
        med, p99 = lat[hop]["median"], lat[hop]["p99"]
        assert math.isfinite(med) and 0.5 < med <= p99 < 2000.0, (hop, lat[hop])
    # a frame reaches the arm command before it reaches the projected image
    assert lat[HOPS[0]]["median"] < lat[HOPS[1]]["median"]
    assert (tmp_path / "latency_load.png").stat().st_size > 5_000
