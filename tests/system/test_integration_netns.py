"""The lab's three computers on one machine: network namespaces main, arm1 and arm2 behind a switch.

Each namespace runs its own share of ``launch/lab_sim.yaml`` (``flexsheet launch … --host NAME``), the
controller twins beside their bridges on their own loopback. The full loop must run across the hosts
(fingertip on main → arm targets → bridges on arm1/arm2 → joint states back to main), and a host that
goes away must be seen through heartbeats and handled. Needs root and iproute2 (CI runs as root).
"""

from __future__ import annotations

import json

import pytest
from conftest import MIN_TIPS_HZ

#: the slow tier (tests/run.sh --slow): over a minute of end-to-end work
pytestmark = pytest.mark.slow


def test_full_loop_across_three_hosts_and_a_host_going_away(lab_run):
    """The run (tests/conftest.py ``lab_run``, netns_util.run_lab): the loop closes across the hosts (the
    bridges on arm1/arm2 report ``ok``: targets from the planner on main), the first (6 s) stroke is
    undisturbed, and at the last stroke arm PC 2 goes away (Ctrl-C): main's launcher sees its nodes'
    heartbeats stop."""
    r = lab_run
    main, arm1 = r["main"], r["arm1"]
    assert r["loop"] is None, r["loop"]
    assert r["arm2_gone"] is None, r["arm2_gone"]
    assert r["code"] == 0, "\n".join(main.lines[-60:])
    summary = json.loads((r["out"] / "summary.json").read_text())
    counts = summary["counts"]
    # joint states from both arm hosts reached main's recorder; so did the world's sheet (FK of both)
    assert counts["/arm/left/joint_state"] > 100 and counts["/arm/right/joint_state"] > 50
    assert counts["/world/sheet"] > 100 and counts["/fingertip"] > 100
    assert "6" in summary, "Table I for the 6 s stroke was computed from the three-host run"
    # the loop tracks across the hosts. Three launches saturate the 2-core machine (run queue 10-17), and a
    # node starved for ~1 s now and then (gaps of 1.1 s in /fingertip) costs the stroke's mean
    # dearly: 6 s-stroke means 0.77-1.98 mm over several runs, 6.3 mm once; medians 0.68 and 1.35 mm.
    # A loop that does not track leaves the sheet at home: the chord to the finger's contact grows to
    # ~18 mm at 30 deg (2R sin 15 deg) and ~35 mm at 60 deg, a median of ~18 mm over an even stroke;
    # the median is the test. Table I's accuracy is judged by test_integration_sim (one launch) and
    # the docs, not here. at least 5 Hz of valid fingertips over the 6 s stroke (a sixth of the
    # camera's 30 fps; not a speed test): 77 on a slower day, with three launches on the machine
    row = summary["6"]
    assert row["n"] > MIN_TIPS_HZ * 6 and row["dd_median_mm"] < 5.0, row
    # the left arm's host kept going after arm2 left (its bridge still reported after the loss)
    assert arm1.seen("left arm: ok")
