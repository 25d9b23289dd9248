"""``flexsheet experiment faults --quick``: every attack in one run, against its target (the
attacks themselves are tested in detail in tests/nodes/test_controller_strict.py, test_bag_integrity.py and
tests/system/test_links_heal.py)."""

from __future__ import annotations

import json

from flexsheet.experiments.faults.experiment import main


def test_every_attack_meets_its_target_in_quick_mode(tmp_path):
    code = main(["--out", str(tmp_path), "--quick"])
    res = json.loads((tmp_path / "faults.json").read_text())
    r = res["results"]
    assert res["quick"] and "never_reading_subscriber" not in r
    assert r["recorder_malformed"]["lost"] == 0 and r["recorder_malformed"]["in_bag"] == r[
        "recorder_malformed"]["fed"]
    assert r["recorder_malformed"]["malformed_stored_raw"] == 6  # 10 hostile: 6 raw, 4 on the channel
    assert r["bag_flip"]["read"] == r["bag_flip"]["messages"] - r["bag_flip"]["chunk_messages"] > 0
    assert r["bag_cut_recover"]["recovered"] == r["bag_cut_recover"]["complete_chunk_messages"] > 0
    assert not r["bag_cut_recover"]["stock_reader_opens_cut"]
    assert r["mxt_burst"]["executed_step_rad"] == 0.02 or abs(r["mxt_burst"]["executed_step_rad"]
                                                              - 0.02) < 1e-6
    assert r["mxt_burst"]["extra"] == 59 and r["modbus_burst"]["refused"] == 19
    assert r["mxt_replay"]["dropped_counted"] == 3 and r["modbus_estop_network_reset"][
        "network_resets_refused"] == 2
    assert r["planner_future_stamp"]["rejected"] == 1 and r["planner_future_stamp"]["served_after"] == 10
    for variant in ("garbage", "plain_zmtp_vs_curve"):
        assert r[f"squat_{variant}"]["received"] >= 20, r[f"squat_{variant}"]
    assert all(v == "met" for v in res["verdicts"].values()), res["verdicts"]
    assert code == 0 and (tmp_path / "faults.png").stat().st_size > 1000
