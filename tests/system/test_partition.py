"""Partition: in the three-host setup (tests/netns_util.py), main's cable to arm PC 1 is
pulled for 2 s mid-stroke (``ip link set <veth> down`` at the switch, then ``up``). On the wall clock: three
hosts (network namespaces) are three processes and a real network, which one simulated clock cannot span.

Expected: the left arm's bridge on arm1 gets no target for ``target_timeout`` (0.25 s) and holds
(``bridge_status = hold:no_target``, logged as ``left arm: hold:no_target``); main's launcher reports the
left arm PC's nodes lost (no heartbeat for 3 × 0.5 s) and back when the cable returns; the bridge follows
targets again (``left arm: ok``) and its commanded joints never step further than one period at the speed
limit — also across the hold and the return, when the queued stale messages arrive at once (TCP keeps the
connection through a 2 s cut; ZeroMQ delivers what was queued, the bridge's LATEST subscription keeps only
the newest target). The right arm, on its own cable, is not disturbed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from netns_util import CUT_S

from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import decode_any

#: the slow tier (tests/run.sh --slow): over a minute of end-to-end work
pytestmark = pytest.mark.slow

STEP_TOLERANCE = 1.5      # the controller's own refusal threshold (× qd_max · period)


def test_a_2s_cut_to_arm1_holds_that_arm_and_it_recovers_without_a_jump(lab_run):
    """The cut is made in the three-host run's 10 s stroke (tests/conftest.py ``lab_run``, netns_util.run_lab:
    1 s into its stroke phase, ``ip link set <veth> down`` for CUT_S, then ``up``); the run's waits saw the
    hold, main's loss/return report and the bridge's ``ok`` again in time."""
    r = lab_run
    assert r["loop"] is None, r["loop"]
    assert r["cut"] is None, r["cut"]
    t_cut, t_back, t_hold = r["t_cut"], r["t_back"], r["t_hold"]
    assert t_back - t_cut >= CUT_S
    assert t_hold < t_back, "the hold started during the cut"
    assert r["code"] == 0, "\n".join(r["main"].lines[-60:])
    tmp_path = r["out"]

    from flexsheet.arm.kinematics import QD_MAX
    from nodes.arm_bridge.params import ArmBridgeParams

    p = ArmBridgeParams()
    limit = QD_MAX * p.speed_scale * p.period
    states = {"left": [], "right": []}
    for m in read_bag(tmp_path / "lab_sim.mcap", topics=["/arm/left/joint_state", "/arm/right/joint_state"]):
        msg = decode_any(m.frames)
        states[msg.arm].append((msg.header.stamp, msg.header.seq, msg.commanded, msg.bridge_status))
    left = states["left"]
    seqs = np.array([s[1] for s in left])
    # the joint states of the cut were queued, not lost: main's recorder has every one of them
    assert np.all(np.diff(seqs) == 1), np.unique(np.diff(seqs))
    status_cut = {s[3] for s in left if t_cut < s[0] < t_back}
    assert "hold:no_target" in status_cut, status_cut
    assert any(s[3] == "ok" for s in left if s[0] > t_back + 1.0)
    # A controller watchdog trip (the bridge's loop late by 3 periods: a scheduling stall on this
    # shared 2-core machine, not the cut) makes the bridge restart from the measured joints,
    # where the tripped controller holds the arm: that reseed is not a commanded motion, so steps
    # into or out of a trip are left out, and trips must stay rare (the loop runs SCHED_FIFO in
    # launch/lab_sim.yaml; measured 0-1 per arm per run, 3 with two FEM solves running beside the
    # suite, 15-67 at nice -5; 11 and 4 in a clean cold suite, 32-54 with two idle-class FEM
    # solves beside it). A bridge that trips on every late loop would count hundreds.
    trips = {arm: sum(a[3] != "fault:watchdog" and b[3] == "fault:watchdog" for a,
                      b in zip(s, s[1:], strict=False))
             for arm, s in states.items()}
    assert max(trips.values()) <= 15, trips
    pairs = list(zip(left, left[1:], strict=False))
    reseed = ["fault:watchdog" in (a[3], b[3]) for a, b in pairs]
    # ... and none may hide the return of the cable, the step this test exists for
    assert not any(r and t_back - 0.1 <= b[0] <= t_back + 1.0 for r,
                   (_, b) in zip(reseed, pairs, strict=True)), \
        "a watchdog trip at the cable's return"
    steps = np.array([np.max(np.abs(b[2] - a[2]) / limit) for r,
                      (a, b) in zip(reseed, pairs, strict=True) if not r])
    assert steps.max() <= STEP_TOLERANCE + 1e-6, steps.max()
    # the other arm went on following targets through the cut
    right_cut = {s[3] for s in states["right"] if t_cut + 0.5 < s[0] < t_back}
    assert "ok" in right_cut, right_cut
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"]["/arm/left/joint_state"] > 100
    print(f"partition: hold after {t_hold - t_cut:.2f} s, largest commanded step {steps.max():.2f} × limit, "
          f"watchdog trips {trips}")
