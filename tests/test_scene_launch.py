"""The whole simulated display on another scene, end to end (issue 17): ``flexsheet launch launch/sim.yaml --set
scene=launch/scenes/sphere.yaml`` — every node takes the sphere, and the report's summary names the scene and
has the stroke's Table I (Δθ) row measured on the sphere."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_sim_launch_on_the_sphere_scene_reports_the_scene_and_dtheta(tmp_path):
    res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--set",
                          "scene=launch/scenes/sphere.yaml", "--duration", "25", "--out", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    out = res.stdout + res.stderr
    assert (tmp_path / "summary.json").exists(), out[-6000:]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["scene"]["name"] == "sphere" and s["scene"]["kind"] == "sphere", s["scene"]
    assert s["scene"]["file"].endswith("sphere.yaml") and s["scene"]["source"] == "launch file scene"
    row = s["10"]                                          # the 10 s stroke, measured on the sphere
    assert row["n"] > 100 and "paper" not in row           # the paper's row belongs to its cylinder
    assert math.isfinite(row["dtheta_mean_deg"]) and 0.0 < row["dtheta_mean_deg"] < 10.0, row   # 1.4° measured
    assert math.isfinite(row["dd_mean_mm"]) and row["dd_2r_mean_mm"] > 0.0     # the sphere has a radius
    comp = s["compliance"]["10"]                           # the tension the planner set at the contacts
    assert comp["n"] > 100 and comp["tension_n_per_m"]["median"] > 0.0
    assert "scene: sphere" in out and res.returncode in (0, 1), out[-4000:]
    # the world's finger followed the sphere's path: every /world/finger sample of the stroke on the sphere
    from flexsheet.runtime.bag import read_bag
    from flexsheet.runtime.codec import decode_any

    c, R = np.array([-0.025 * math.sqrt(2.0), 0.0, 0.0]), 0.025 * math.sqrt(2.0)
    r = [np.linalg.norm(m.position - c) for m in (decode_any(x.frames) for x in
                                                    read_bag(tmp_path / "sim.mcap", topics=["/world/finger"]))
         if m.phase == "stroke"]
    assert len(r) > 500 and abs(np.median(r) - (R - 0.0005)) < 2e-4
