"""The whole simulated display on another scene, end to end: ``flexsheet launch launch/sim.yaml --set
scene=launch/scenes/sphere.yaml`` — every node takes the sphere, and the report's summary names the scene and
has the stroke's Table I (Δθ) row measured on the sphere; the organ with its stiff inclusion: the FEM solves
the organ (its messages carry the organ's scene key) and its stiffness peak over the inclusion reaches the
sheet's tension along the stroke.

The graph runs on the simulated clock (launch/sim.yaml ``clock: sim``): simulated time starts once every node,
the FEM included, is active, so the stroke is served by the FEM from its start whatever the host's load."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import MIN_TIPS_HZ

ROOT = Path(__file__).resolve().parents[2]

MIN_TIPS = int(MIN_TIPS_HZ * 10)      # a 10 s stroke


def _warm_fem(name: str) -> str:
    """Precompute (or load) the FEM node's model of scene ``name`` in the default cache; its scene key."""
    from flexsheet.fem.scene_model import SceneModel
    from flexsheet.model.scenes import load_scene

    return SceneModel(load_scene(ROOT / "launch" / "scenes" / f"{name}.yaml")).scene_key


def _bag(path, topic):
    from flexsheet.runtime.bag_read import read_bag
    from flexsheet.runtime.codec import decode_any

    return [decode_any(x.frames) for x in read_bag(path, topics=[topic])]


def test_sim_launch_on_the_sphere_scene_reports_the_scene_and_dtheta(tmp_path):
    """The planner's tension from the FEM's dF/dd of the sphere (~65 N/m at a 0.5 mm stroking contact, 1.4 x
    Hertz's tangent: its imposed-overlap contact), which holds the sheet at its 40 N clamp-force stretch most
    of the stroke; Δθ 0.58° measured (0.62° with the planner's own Hertz estimate). An earlier 4.7–20.9° was a
    table-building worker beside the graph (docs/renderer.md), not the sphere."""
    key = _warm_fem("sphere")
    # the 10 s stroke alone (the default script's first segment): the run ends with it (world exits, 13 s of
    # script) instead of being cut by --duration inside the 30 s stroke that follows it. --duration is only a
    # cap: at 25 s a slow start (the world's script began ~17 s in) cut the stroke at 20 %
    res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--set",
                          "scene=launch/scenes/sphere.yaml", "--set", "world.script=[{mode: stroke, "
                                                                      "moving_time: 10}]",
                          "--duration", "60", "--out", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    out = res.stdout + res.stderr
    assert (tmp_path / "summary.json").exists(), out[-6000:]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["scene"]["name"] == "sphere" and s["scene"]["kind"] == "sphere", s["scene"]
    assert s["scene"]["file"].endswith("sphere.yaml") and s["scene"]["source"] == "launch file scene"
    row = s["10"]                                          # the 10 s stroke, measured on the sphere
    assert row["n"] > MIN_TIPS and "paper" not in row      # the paper's row belongs to its cylinder
    assert math.isfinite(row["dtheta_mean_deg"]) and 0.0 < row["dtheta_mean_deg"] < 10.0, row  # 1.4° measured
    assert math.isfinite(row["dd_mean_mm"]) and row["dd_2r_mean_mm"] > 0.0     # the sphere has a radius
    comp = s["compliance"]["10"]                           # the tension the planner set at the contacts
    assert comp["n"] > MIN_TIPS and comp["tension_n_per_m"]["median"] > 0.0
    assert "scene: sphere" in out and res.returncode in (0, 1), out[-4000:]
    # the world's finger followed the sphere's path: every /world/finger sample of the stroke on the sphere
    from flexsheet.runtime.bag_read import read_bag
    from flexsheet.runtime.codec import decode_any

    c, R = np.array([-0.025 * math.sqrt(2.0), 0.0, 0.0]), 0.025 * math.sqrt(2.0)
    r = [np.linalg.norm(m.position - c) for m in (decode_any(x.frames) for x in
                                                    read_bag(tmp_path / "sim.mcap", topics=["/world/finger"]))
         if m.phase == "stroke"]
    assert len(r) > MIN_TIPS and abs(np.median(r) - (R - 0.0005)) < 2e-4
    # the FEM solved the sphere: its deformations name it, and their contact points lie on the sphere
    de = [m for m in _bag(tmp_path / "sim.mcap", "/object/deformation") if m.valid and m.depth > 0]
    assert len(de) > 50 and {m.scene_key for m in de} == {key}
    cp = np.array([m.contact_point for m in de])
    assert np.abs(np.linalg.norm(cp - c, axis=1) - R).max() < 2e-4


# the tension's peak rides on the arms' lag behind the stiffness: +18 % and +7.5 % in some runs, but
# +2 % and -0.5 % in two of three cold suites (the FEM's own peak held, +8 % or more, every time).
# One rerun on failure (pytest-rerunfailures); the tension peak is weak (docs/scenes.md).
@pytest.mark.flaky(reruns=1)
def test_sim_launch_on_the_organ_shows_the_fem_stiffness_peak_over_the_inclusion_in_the_tension(tmp_path):
    """Palpation along the organ: a 3 mm stroke (the default 0.5 mm stroking contact feels the 8 mm-deep
    tumour by only ~5 %, within the FEM mesh's scatter) and the sheet asked for 0.5 x the organ's stiffness
    (the identified sheet presents ~37-90 N/m at 3 mm, from its least stretch to the arms' pull limit; the
    organ is ~100-130 N/m at 3 mm)."""
    from flexsheet.model.scenes import load_scene

    sc = load_scene(ROOT / "launch" / "scenes" / "organ.yaml")
    key = _warm_fem("organ")
    res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--set",
                          "scene=launch/scenes/organ.yaml", "--set",
                          "world.script=[{mode: stroke, moving_time: 10, depth: 0.003}]",
                          "--set", "planner.stiffness_scale=0.5", "--duration", "60", "--out", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    out = res.stdout + res.stderr
    assert (tmp_path / "summary.json").exists(), out[-6000:]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["scene"]["name"] == "organ" and s["scene"]["kind"] == "mesh", s["scene"]
    row = s["10"]
    assert row["n"] > MIN_TIPS and math.isfinite(row["dtheta_mean_deg"]) and 0.0 < row[
        "dtheta_mean_deg"] < 10.0, row
    assert s["compliance"]["10"]["n"] > MIN_TIPS
    assert "scene 'organ'" in out and res.returncode in (0, 1), out[-4000:]
    # bins along the stroke (the organ's long axis, y) from the scene file: over the tumour = within its
    # radius of its centre's y; away = more than 20 mm from it
    inc = sc.inclusions[0]
    y0, r = inc.center[1], inc.radius

    def over_away(y, v):
        y, v = np.asarray(y), np.asarray(v)
        o, a = np.abs(y - y0) <= r, np.abs(y - y0) > 0.020
        assert o.sum() >= 10 and a.sum() >= 10, (o.sum(), a.sum())
        return float(np.median(v[o])), float(np.median(v[a]))

    # the FEM was up before the stroke began (world.start_after): its first deformation precedes the stroke
    stroke = [m.header.stamp for m in _bag(tmp_path / "sim.mcap", "/world/finger") if m.phase == "stroke"]
    first = min(m.header.stamp for m in _bag(tmp_path / "sim.mcap", "/object/deformation"))
    assert first < stroke[0], (first - stroke[0], out[-3000:])
    de = [m for m in _bag(tmp_path / "sim.mcap", "/object/deformation") if m.valid and m.depth > 0.002]
    assert len(de) > 50 and {m.scene_key for m in de} == {key}     # the FEM solved this organ
    k_over, k_away = over_away([m.contact_point[1] for m in de], [m.stiffness for m in de])
    assert k_over > 1.08 * k_away, (k_over, k_away)                # measured 158 vs 132 N/m (+19 %)
    tg = [m for m in _bag(tmp_path / "sim.mcap", "/sheet/target") if m.touching
          and not m.status.startswith("hold")]
    t_over, t_away = over_away([m.contact_point[1] for m in tg], [m.tension for m in tg])
    # the tension follows the stiffness through the arms' response, which lags it by a few mm of stroke:
    # measured 19.1 vs 16.5 N/m (+16 %; the identified sheet carries much of the force itself at low tension)
    assert t_over > 1.05 * t_away, (t_over, t_away)
