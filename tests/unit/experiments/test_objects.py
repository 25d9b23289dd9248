"""``flexsheet experiment objects``: the per-object figures from a run's summary and bag, and their verdicts
(flexsheet/experiments/objects.py)."""

from __future__ import annotations

import numpy as np

from flexsheet.experiments.objects import TARGETS, bridge_holds, measure_object, verdicts
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.codec import encode
from messages import ArmJointState, Header


def _summary(felt30=0.2, within=0.97, span=0.5, lag=12.0) -> dict:
    return {"table1": {"felt": {"10": {"dtheta_mean_deg": 0.15}, "30": {"dtheta_mean_deg": felt30}}},
            "delay": {"residual_lag_ms": lag},
            "placement": {"touches": 3, "arrivals": 3, "sheet_first": 1.0, "late": 0, "never": 0,
                          "onsets": {"in_place_and_pose": 2 / 3}, "distance_mm": {"p99": 0.6}},
            "compliance": {"felt": {"within_15pct": within}, "saturated": 0.01, "follow_ms": 40.0},
            "sheet": {"span_error_mm": {"p99": span}, "strain_over_plan_max": 0.005},
            "safety": {"keepout_violations": 0}}


def test_an_object_is_judged_against_each_target_and_the_cylinder():
    m = measure_object(_summary(), None, "fem: ... serving the LINEAR model (build it ...)")
    assert m["felt_dtheta_deg"] == {"10": 0.15, "30": 0.2} and m["fem_model"] == "linear"
    assert m["landings"]["in_place_and_pose"] == 2 / 3 and m["bridge_holds"] == 0
    v = verdicts(m, cyl30=0.13)
    assert set(v) == set(TARGETS) and all(x == "met" for x in v.values())
    bad = measure_object(_summary(felt30=0.3, within=0.9, span=1.5, lag=40.0), None)
    v = verdicts(bad, cyl30=0.13)                       # 0.3 > 2 × 0.13
    assert {k for k, x in v.items() if x == "MISSED"} == {"felt_30_vs_cylinder", "force_within_15pct",
                                                          "span_p99_mm", "residual_lag_ms"}
    assert verdicts(bad, cyl30=None)["felt_30_vs_cylinder"] == "not measured"
    empty = measure_object({}, None)
    assert empty["felt_dtheta_deg"] == {"10": None, "30": None}
    assert verdicts(empty, 0.13)["span_p99_mm"] == "not measured"


def test_bridge_holds_count_refusals_not_a_bridge_before_its_first_target(tmp_path):
    path = tmp_path / "run.mcap"
    statuses = ["hold:no_target", "hold:disabled", "ok", "hold:limit:J3", "hold:limit:J3", "hold:peer", "ok"]
    w = BagWriter(path)
    z6 = np.zeros(6)
    for i, s in enumerate(statuses):
        msg = ArmJointState(header=Header(stamp=1000.0 + i), arm="left", position=z6, velocity=z6,
                            commanded=z6, executing=z6, pose=np.eye(4), status=0, bridge_status=s)
        w.write(encode("/arm/left/joint_state", msg), int((1000.0 + i) * 1e9))
    w.close()
    assert bridge_holds(path) == {"hold:limit:J3": 2, "hold:peer": 1}
