"""Which strokes the two arms can present at all (flexsheet.experiments.reach): the home sheet is presentable
by the paper's rule, a plane turned far from the arms is not by any pose, and the paper's cylinder's stroke is
wholly presentable by the paper's rule."""

from __future__ import annotations

import math

import numpy as np

from flexsheet.experiments.reach import presentable, stroke_reach
from flexsheet.model import geometry
from flexsheet.model.scenes import load_scene_or_paper
from flexsheet.planning.arm_reach import ArmReach

BASES = {"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE}


def test_the_home_sheet_is_presentable_and_a_plane_facing_away_is_not():
    reach = ArmReach(BASES)
    o = np.zeros(3)
    home = presentable(reach, o, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), (0.0, 0.0), {})
    a = math.radians(80.0)                      # the sheet turned 80° about the vertical: edge-on to the user
    n = np.array([math.cos(a), math.sin(a), 0.0])
    axes = (np.array([0.0, 0.0, 1.0]), np.cross((0.0, 0.0, 1.0), n))     # the clamp axis up, or level
    turned = [presentable(reach, o, n, u, (0.0, 0.0), {}) for u in axes]
    assert home and not any(turned)


def test_the_papers_cylinder_stroke_is_presentable_by_the_papers_rule():
    r = stroke_reach(load_scene_or_paper(None), 4)
    assert r["share"] == {"paper": 1.0, "psi": 1.0, "any": 1.0}
    assert abs(r["largest_tilt_asked_deg"] - 60.0) < 0.5         # the stroke goes 0° → 60° around its axis
    assert [round(s["tilt_deg"]) for s in r["samples"]] == [0, 20, 40, 60]
