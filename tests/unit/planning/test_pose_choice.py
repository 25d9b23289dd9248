"""The sheet's in-plane rotation ψ between touches (flexsheet.planning.pose_choice): the paper's rule kept
where it is as good, a better ψ taken where the arms reach farther with it, none while touching, and no flip
on a tie."""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.shapes import make_shape, paper_cylinder
from flexsheet.planning.arm_reach import ArmReach
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.pose_choice import PoseChoice
from flexsheet.planning.surface_planner import SurfacePlanner

BASES = {"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE}
R = geometry.CYLINDER_RADIUS
C = np.array(geometry.CYLINDER_CENTER)
DT = 1.0 / 48.0


def _planner(shape, **cfg) -> SurfacePlanner:
    return SurfacePlanner(shape, PlannerConfig(jump_distance=1.0, **cfg), arm_reach=ArmReach(BASES))


def _hover_then_stroke(pl, degs: float, axis_z: bool):
    """Hover 30 mm off the cylinder for 1.25 s, then touch and stroke ``degs`` around its axis at 24°/s."""
    for k in range(60):
        pl.update(k * DT, C + np.array([R + 0.03, 0.0, 0.0]))
    psi = pl.pose_choice.psi if pl.pose_choice is not None else 0.0
    plans = []
    for k in range(60, 60 + int(degs / 0.5) + 40):
        a = math.radians(min(degs, (k - 60) * 0.5))
        d = (math.cos(a), math.sin(a), 0.0) if axis_z else (math.cos(a), 0.0, -math.sin(a))
        plans.append(pl.update(k * DT, C + (R - 0.0005) * np.array(d)))
    return psi, plans


def test_the_paper_cylinder_keeps_the_papers_rule():
    pl = _planner(paper_cylinder())
    psi, plans = _hover_then_stroke(pl, 40.0, axis_z=False)
    s = pl.pose_choice.scores
    assert psi == 0.0 and pl.pose_choice.evaluations >= 5
    assert s[0.0] > max(v for k, v in s.items() if k != 0.0) + pl.cfg.psi_hysteresis   # clearly the best
    ref = _hover_then_stroke(_planner(paper_cylinder(), psi_range=0.0), 40.0, axis_z=False)[1]
    assert max(abs(np.dot(p.axis_u, r.axis_u) - 1.0) for p, r in zip(plans, ref, strict=True)) < 1e-12


def test_an_upright_cylinder_takes_the_psi_the_arms_follow_farther():
    shape = make_shape("cylinder", {"axis": (0.0, 0.0, 1.0)})
    pl = _planner(shape)
    psi, plans = _hover_then_stroke(pl, 60.0, axis_z=True)
    s = pl.pose_choice.scores
    assert math.degrees(psi) == 10.0                          # the arms reach at most about ±15° from home
    assert s[psi] > s[0.0] + pl.cfg.psi_hysteresis            # a look-ahead roll the paper's ψ cannot take
    paper = _hover_then_stroke(_planner(shape, psi_range=0.0), 60.0, axis_z=True)[1]
    turned = [math.degrees(math.atan2(p[-1].normal[1], p[-1].normal[0])) for p in (plans, paper)]
    assert turned[0] > turned[1] + 1.0                        # 34.5° against 32.9° of the 60° asked


def test_no_change_of_psi_while_touching():
    pl = _planner(make_shape("cylinder", {"axis": (0.0, 0.0, 1.0)}))
    psi, plans = _hover_then_stroke(pl, 30.0, axis_z=True)
    n_eval = pl.pose_choice.evaluations
    assert all(p.touching for p in plans[1:])
    assert pl.pose_choice.psi == psi and pl.pose_choice.evaluations == n_eval   # no sweep while touching
    pl.pose_choice.psi = 0.3                                  # even a changed choice does not turn the sheet
    nxt = pl.update(plans and (60 + len(plans)) * DT, plans[-1].contact)
    assert np.allclose(nxt.axis_u, plans[-1].axis_u, atol=1e-6)


def test_a_tie_does_not_flip_and_the_paper_rule_wins_within_the_hysteresis():
    ch = PoseChoice(paper_cylinder(), PlannerConfig(), ArmReach(BASES))
    a = math.radians(10.0)
    ch.psi = a
    assert ch.decide({0.0: 0.20, a: 0.20}) == a               # a tie: the current choice stays
    assert ch.decide({0.0: 0.20, a: 0.20, -a: 0.24}) == a     # better by less than the hysteresis: stays
    assert ch.decide({0.0: 0.30, a: 0.20, -a: 0.32}) == 0.0   # clearly worse: back to the paper's rule
    assert ch.decide({0.0: 0.20, a: 0.20, -a: 0.32}) == -a    # and only a clear gain leaves it


def test_a_candidate_whose_pose_does_not_solve_is_never_taken():
    ch = PoseChoice(paper_cylinder(), PlannerConfig(), ArmReach(BASES))
    a, inf = math.radians(10.0), math.inf
    ch.psi = a
    assert ch.decide({0.0: -inf, a: -inf, -a: -inf}) == a     # none solves: the current ψ stays
    assert ch.decide({0.0: -9.0, a: -inf, -a: -inf}) == 0.0   # the current fails, the paper's pose solves
    ch.psi = a
    assert ch.decide({0.0: -inf, a: -7.0, -a: -inf}) == a     # only the current solves: it stays
    assert ch.decide({0.0: -inf, a: -inf, -a: 0.1}) == -a     # the one that solves, however far
