"""The stroke model experiment (flexsheet.experiments.stroke_model): with the arm twin's datasheet speeds the
planner's stroke (and stroke + push) stays reachable and within the bridge's commanded speed on the realistic
twin, three truth seeds; the quick run writes its summary."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.experiments.stroke_model import ArmChain, make_twin, simulate


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stroke_and_push_fit_the_datasheet_speeds_on_the_realistic_twin(seed):
    stats: dict = {}
    row = simulate(10.0, make_twin("realistic", seed), seed=seed, stats=stats,
                   finger_kw={"mode": "stroke_push", "push_depth": 0.010})
    assert stats["ik_refused"] == 0                                   # every target reachable by the IK
    assert stats["peak_joint_speed_ratio"] < ArmChain().speed_scale   # below the bridge's command limit
    assert row["n"] > 300 and row["dtheta_mean_deg"] < 2.0


def test_experiment_quick_writes_summary(tmp_path, monkeypatch):
    """The stroke experiment's quick run (pure computation, no node: phase 1 of tests/run.sh)."""
    import json

    from flexsheet.experiments import stroke_model as experiment

    monkeypatch.setattr(experiment, "plot_chart", lambda *a, **k: None)   # chart drawing is not under test
    assert experiment.main(["--out", str(tmp_path), "--seeds", "1", "--quick"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    R = experiment.paper_cylinder().R
    for rows in (s, s["ideal"]):
        for k in ("10", "30"):
            for f in ("dd_mean_mm", "dd_std_mm", "dtheta_mean_deg", "dtheta_std_deg", "dd_2r_mean_mm"):
                assert np.isfinite(rows[k][f]) and rows[k][f] > 0
            # both Δd conventions: the chord ≈ R·Δθ and the paper's 2R·Δθ
            assert rows[k]["dd_2r_mean_mm"] == pytest.approx(2e3 * R * np.radians(rows[k]["dtheta_mean_deg"]))
            assert rows[k]["dd_mean_mm"] == pytest.approx(rows[k]["dd_2r_mean_mm"] / 2, rel=1e-3)
    assert s["twin"]["realism"] == "realistic" and s["twin"]["estimator_bases"].startswith("nominal")
    # the launch file's filter: q and horizon of launch/sim.yaml's triangulator
    assert s["filter"]["file"] == "sim.yaml" and s["filter"]["horizon_s"] > 0
    # 8 + 3 + 1 ms to the arm PC, 3.55 ms tick wait, 7.1 ms pipeline tick, 15 ms servo lag
    assert s["latency_budget_ms"] == pytest.approx(8 + 3 + 1 + 3.55 + 7.1 + 15, abs=0.01)
    # the realistic twin (truth, camera noise) is worse than the ideal one; prediction pays at 10 s
    assert s["10"]["dtheta_mean_deg"] > s["ideal"]["10"]["dtheta_mean_deg"]
    assert s["10"]["dtheta_mean_deg"] < s["10_no_prediction"]["dtheta_mean_deg"]
    assert s["noise_floor"]["dtheta_floor_deg"] < s["10"]["dtheta_mean_deg"]
    chart = json.loads((tmp_path / "stroke_errors.json").read_text())
    lat = chart["by_latency"]["no_prediction"]
    assert lat[-1]["dtheta_mean_deg"] > lat[0]["dtheta_mean_deg"]     # more latency, more error
