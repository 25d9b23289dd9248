"""Where the finger will land (flexsheet.planning.landing.FingerPath) and the planner's sheet placed there before
the touch: the path against the surface, against the nearest point, at rest, moving away and at the turn."""

from __future__ import annotations

import numpy as np

from flexsheet.model.shapes import make_shape
from flexsheet.model.vec import dot, norm, sub
from flexsheet.planning.landing import FingerPath
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner

DT = 1.0 / 60.0
SPHERE = {"center": (-0.04, 0.0, 0.0), "radius": 0.04}


def _approach(speed=0.1, angle_deg=50.0):
    """A straight path onto the sphere at an angle to its normal at the landing L (on the sphere, 30° up from
    its pole toward the user): the landing L (3,) m, the velocity (3,) m/s and the position at time t before it."""
    c = np.array(SPHERE["center"])
    n = np.array([np.cos(np.radians(30.0)), 0.0, np.sin(np.radians(30.0))])
    L = c + SPHERE["radius"] * n
    tang = np.cross(n, [0.0, 1.0, 0.0])
    a = np.radians(angle_deg)
    v = speed * (-np.cos(a) * n + np.sin(a) * tang)
    return L, v, lambda t: L - v * t


def test_the_landing_is_where_the_path_meets_the_surface_not_the_nearest_point():
    s = make_shape("sphere", SPHERE)
    L, v, at = _approach()
    cfg = PlannerConfig(landing_horizon=2.0)          # look far ahead: the path's own geometry is checked
    fp = FingerPath()
    errs = {}
    for k in range(60, 0, -1):                        # 1 s of samples, up to 1 frame before the landing
        t = k * DT
        p = tuple(at(t))
        fp.observe(p, DT if k < 60 else None, cfg.velocity_tau)
        if k in (30, 12):                             # 0.5 s and 0.2 s before: 32 and 13 mm to travel
            proj = s.project(p, None)
            land = fp.landing(s, p, proj, cfg)
            errs[k] = (norm(sub(land.point, tuple(L))), norm(sub(proj.point, tuple(L))))
    assert np.allclose(fp.v, v, atol=1e-9)
    assert errs[12][0] < 0.5e-3 and errs[12][1] > 8e-3, errs
    assert errs[30][0] < 0.5e-3 and errs[30][1] > 15e-3, errs


def test_at_rest_moving_away_or_along_the_surface_it_is_the_nearest_point():
    s = make_shape("sphere", SPHERE)
    cfg = PlannerConfig()
    p = (0.01, 0.0, 0.01)
    proj = s.project(p, None)
    for step in ((0.0, 0.0, 0.0), tuple(0.001 * x for x in proj.normal), (0.0, 0.002, 0.0)):
        fp = FingerPath()
        fp.observe(sub(p, step), None)
        fp.observe(p, DT)
        assert fp.landing(s, p, proj, cfg) == proj
    fp.observe(p, None)                               # no step: the velocity is forgotten
    assert fp.v is None and fp.landing(s, p, proj, cfg) == proj


def test_the_landing_moves_continuously_as_the_closing_speed_turns():
    """The regularised time to contact has no jump where the finger turns from leaving to closing."""
    s = make_shape("sphere", SPHERE)
    cfg = PlannerConfig()
    p = (0.012, 0.0, 0.0)
    proj = s.project(p, None)
    pts = []
    for c in np.linspace(-0.01, 0.01, 401):          # closing speed m/s, with 0.05 m/s along the surface
        fp = FingerPath()
        fp.v = (-c, 0.0, 0.05)
        pts.append(np.array(fp.landing(s, p, proj, cfg).point))
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps.max() < 3e-4, steps.max()           # 0.05 mm/s of closing speed apart
    assert np.linalg.norm(pts[-1] - pts[0]) > 2e-3    # it does move: toward the landing


def test_the_planner_turns_the_sheet_to_the_landing_before_the_touch():
    s = make_shape("sphere", SPHERE)
    L, v, at = _approach()
    n_land = sub(tuple(L), SPHERE["center"])
    n_land = tuple(x / norm(n_land) for x in n_land)
    pl = SurfacePlanner(s)
    plan = None
    for k in range(60, 11, -1):                        # until 0.2 s before the landing, 13 mm to travel
        plan = pl.update((60 - k) * DT, tuple(at(k * DT)))
    assert not plan.touching
    assert dot(plan.normal, n_land) > np.cos(np.radians(2.0)), plan.normal
    assert norm(sub(plan.contact, tuple(L))) < 1.5e-3
