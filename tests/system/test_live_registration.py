"""The display registered from the live graph, end to end: ``launch/lab_sim.yaml`` on three network namespaces
(the lab's protocols: CURVE, the MXT controller twins on the arm hosts, the camera twin on main) under a truth
seed drawn for this run, and ``flexsheet calibrate display --live`` run on main moving the arms through their
bridges, showing the Gray code through the renderer and averaging the camera's frames. Its estimates must meet
the registration targets against that seed's hidden truth. Needs root and iproute2 (CI runs as root).
"""

from __future__ import annotations

import json
import random
import subprocess
import sys

import pytest
from netns_util import ROOT, HostLaunch, three_hosts

from flexsheet.twin.registration import TARGETS, sim_display_calib


@pytest.mark.timeout(1500)   # ~7 min on the 2-core machine: the graph's start, ~480 captures, the fits
def test_live_registration_meets_the_targets_for_a_drawn_truth(tmp_path, sim_fem_cache):
    seed = random.SystemRandom().randrange(10, 100_000)     # the full preset: --quick misses the projector target on
    # some draws (2.47 mm on truth 34949 with one noise draw)
    print(f"truth seed {seed}")                                    # shown with the failure
    sim_display_calib(seed, "realistic")      # the graph's own registration, once here instead of per host
    sets = ["--set", f"twin.truth_seed={seed}", "--set", "world.loop=true", "--duration", "900"]
    out = tmp_path / "live"
    with three_hosts() as ns:
        hosts = [HostLaunch(ns["arm1"], "arm1", *sets), HostLaunch(ns["arm2"], "arm2", *sets),
                 HostLaunch(ns["main"], "main", "--out", str(tmp_path / "launch"), *sets)]
        try:
            hosts[0].wait("left arm: ok", 120)
            hosts[1].wait("right arm: ok", 120)
            r = subprocess.run(["ip", "netns", "exec", ns["main"], sys.executable, "-m", "flexsheet", "calibrate",
                                "display", "--live", "--launch", "launch/lab_sim.yaml", "--host", "main",
                                "--truth-seed", str(seed), "--out", str(out)],
                               cwd=ROOT, capture_output=True, text=True, timeout=900)
        finally:
            for h in hosts:
                h.stop()
    assert r.returncode == 0, f"seed {seed}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    s = json.loads((out / "summary.json").read_text())
    assert s["mode"] == "live" and s["seed"] == seed and s["targets"] == TARGETS
    c, p = s["camera"], s["projector"]
    assert c["translation_error_mm"] <= TARGETS["camera_mm"] and c["rotation_error_deg"] <= TARGETS["camera_deg"], c
    assert p["translation_error_mm"] <= TARGETS["projector_mm"], p
    assert p["rotation_error_deg"] <= TARGETS["projector_deg"] and p["reprojection_px"] <= TARGETS["projector_px"], p
    for side in ("left", "right"):
        assert s["arms"][side]["translation_error_mm"] <= TARGETS["arms_mm"], (side, s["arms"][side])
    assert all(s["verdicts"].values()), s["verdicts"]
    # the captures are in the images layout: the fit can be re-run offline from them
    man = json.loads((out / "frames" / "manifest.json").read_text())
    assert len(man["arms"]["left"]["joints"]) == s["arms"]["left"]["configs"]
    assert len(list((out / "frames" / "camera_pose").glob("view*_left.png"))) == s["camera"]["views"]
    assert "display.yaml" in {f.name for f in out.iterdir()}
