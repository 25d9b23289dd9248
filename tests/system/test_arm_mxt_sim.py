"""The paper's stroking run (Table I, 10 s stroke) through the whole simulated graph with both arms on MELFA
real-time external control (MXT/UDP twins) instead of Modbus:
``flexsheet launch launch/sim_composed.yaml --set arm_left.protocol=mxt --set ctrl_left.protocol=mxt
...`` ("the full stroking run must pass through MXT twins too"). Heavy (one sim launch, ~30 s on 2 cores). On
the wall clock: the MXT session is paced by the controller's own 7.11 ms clock (the bridge answers its
replies), which a simulated clock cannot drive."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import MIN_TIPS_HZ, private_ports

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.kinematics import QD_MAX
from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import decode_any

ROOT = Path(__file__).resolve().parents[2]
MXT = ["arm_left.protocol=mxt", "ctrl_left.protocol=mxt", "arm_right.protocol=mxt", "ctrl_right.protocol=mxt"]
SCRIPT = "world.script=[{mode: stroke, moving_time: 10}]"
#: the slow tier (tests/run.sh --slow): a 150 s wall-clock run of the whole graph
pytestmark = pytest.mark.slow


# a 150 s real-time run of the whole graph on a shared 2-core machine. The servo is judged against the command
# the controller reports executing in the same reply (ArmJointState.executing, the MXT
# JOINT slot), not against the bridge's newest send: that one also carries the host
# link's delay, and when the twin's process is descheduled for tens of ms while the arm
# moves (up to half the datasheet speeds) it reads as servo lag (CI of 2026-11-24, both
# attempts: p95 1.8 deg against the command sent; two busy loops beside the run here:
# max 5.7 deg). The link is judged by its own counters (lost, refused). One rerun on
# failure; the rerun must meet every assertion (pytest-rerunfailures, `-rR` lists it).
@pytest.mark.flaky(reruns=1)
def test_table1_stroke_through_mxt_twins(tmp_path, sim_fem_cache):
    # sim_fem_cache: the FEM's precompute is in the disk cache before the launch (tests/conftest.py), so the
    # measured run starts as every later run does instead of starving the 2-core machine with it
    # an offset other than test_faults' default, so the two never share ports within one pytest process
    launch = private_ports(ROOT / "launch" / "sim_composed.yaml", tmp_path / "sim_mxt.yaml",
                           offset=100 * (1 + (os.getpid() + 60) % 120))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "flexsheet", "launch", str(launch), "--out", str(out), "--duration", "150",
           "--set", SCRIPT]
    for s in MXT:
        cmd += ["--set", s]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-6000:] + res.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    row = summary["10"]
    # the arms carried the sheet over MXT: on the honest (realistic) twin the sheet follows
    # the finger's tangent plane as over Modbus, with the same bounds
    # (tests/system/test_integration_sim.py: median and mean, for a loaded 2-core machine; the
    # realistic camera's noise floor keeps both above the paper's 0.359 deg, docs/planner.md)
    assert row["n"] > MIN_TIPS_HZ * 10                    # the 10 s stroke (conftest: not a speed test)
    assert 0.0 < row["dtheta_median_deg"] < 1.5 and row["dtheta_mean_deg"] < 2.0, row

    states = {"left": [], "right": []}
    beats: dict[str, str] = {}
    for m in read_bag(out / "sim.mcap",
                      topics=["/arm/left/joint_state", "/arm/right/joint_state", "/diagnostics"]):
        msg = decode_any(m.frames)
        if m.topic == "/diagnostics":
            beats[msg.node] = msg.message
        else:
            states[msg.arm].append(msg)
    step_limit = BridgeConfig().speed_scale * QD_MAX * 0.00711     # the bridge's speed at the MXT cycle
    for arm in ("left", "right"):
        st = states[arm]
        assert len(st) > 1000, (arm, len(st))     # ~140 Hz over the run
        ok = np.mean([m.bridge_status == "ok" for m in st])
        assert ok > 0.5, (arm, ok)
        cmd_q = np.array([m.commanded for m in st])
        assert np.all(np.abs(np.diff(cmd_q, axis=0)) <= step_limit * (1 + 1e-6)), arm
        # FB_JOINT follows the command it executes: median within 0.6 deg, 95 % of the
        # cycles within 1.2 deg (the datasheet joint speeds and the 15 ms servo lag)
        lag = np.array([np.max(np.abs(m.position - m.executing)) for m in st])
        assert (np.median(lag) < 0.01 and np.percentile(lag, 95) < 0.02), (arm, np.median(lag),
                                                                           np.percentile(lag, 95))
        # and what it executes is what the bridge sent, a cycle or so behind: the median
        # gap is a small part of one speed-limited step (0.05-0.06 of it measured alone
        # and beside 2-4 busy processes); an `executing` that were not the controller's
        # echo of these commands (zeros, another arm's) would be many steps off
        behind = np.array([np.max(np.abs(m.executing - m.commanded) / step_limit) for m in st])
        assert np.median(behind) < 0.5, (arm, np.median(behind))
        twin = _counters(beats[f"ctrl_{arm}"].split("mxt session")[1])          # the twin's last heartbeat
        assert twin["moves"] > 1000 and twin["refused"] == 0, twin
        link = _counters(beats[f"arm_{arm}"].split("mxt:")[1])                   # the bridge's last heartbeat
        assert link["sent"] > 1000 and link["refused"] == 0, link
        assert link["lost"] <= 0.01 * link["sent"], link


def _counters(text: str) -> dict[str, int]:
    return {k: int(v) for k, v in re.findall(r"(\w+) (\d+)", text)}
