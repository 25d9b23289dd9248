"""The planner's stage (flexsheet.planning.planner_stage): which stiffness sets the tension, which FEM
messages count for the scene, and one plan's command to both arms (poses, pull, the pull cap, the shared
motion)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from flexsheet.arm.sheet_motion import SheetSegment
from flexsheet.model.scenes import SCENES_DIR, load_scene, paper_scene
from flexsheet.model.tension import clamp_force
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.planner_stage import PlannerStage, StageConfig, fem_solves_scene
from flexsheet.planning.pull_guard import PullGuard


def _params(object_stiffness: float = 30.0, **kw) -> StageConfig:
    return StageConfig(planner=PlannerConfig(object_stiffness=object_stiffness), **kw)


def test_a_fem_message_counts_only_for_the_scene_it_names():
    organ, sphere = load_scene(SCENES_DIR / "organ.yaml"), load_scene(SCENES_DIR / "sphere.yaml")
    assert fem_solves_scene(organ.key(), organ)
    assert not fem_solves_scene(organ.key(), sphere)
    assert not fem_solves_scene(sphere.key(), organ, organ.key())
    assert not fem_solves_scene("", organ)                      # unknown: not this organ
    assert fem_solves_scene("", paper_scene())                  # unknown: the old FEM's cylinder
    assert fem_solves_scene(paper_scene().key(), paper_scene())


def test_the_fems_stiffness_sets_the_tension_while_fresh_and_about_this_scene():
    stage = PlannerStage(paper_scene(), _params(fem_window=0.2))
    assert stage.stiffness(0.0) == (None, "scene")              # no FEM yet: the scene's compliance model
    stage.set_fem(1.0, load_scene(SCENES_DIR / "organ.yaml").key(), 500.0, 0.5, 0.003)
    assert stage.stiffness(1.0) == (None, "scene") and stage.fem_other_scene == 1
    key = paper_scene().key()
    for t, k in ((1.0, 100.0), (1.1, 300.0), (1.15, 200.0)):
        stage.set_fem(t, key, k, 0.4, 0.003)
    assert stage.stiffness(1.2) == (200.0, "fem")                # the median of the last 0.2 s
    stage.set_fem(1.2, key, 0.0, 0.0, 0.0)                       # not positive: ignored, the last kept
    assert stage.stiffness(1.2) == (200.0, "fem")
    stage.set_fem(1.25, key, 400.0, 0.4, 0.003)                  # 300, 200 and 400 within 0.2 s of 1.25
    assert stage.stiffness(1.25) == (300.0, "fem")
    assert stage.stiffness(1.25 + 0.51)[1] == "scene"            # stale after fem_timeout
    no_model = PlannerStage(paper_scene(), _params(stiffness_from_scene=False, object_stiffness=42.0))
    assert no_model.stiffness(0.0) == (42.0, "param")


def test_one_plan_gives_both_arms_one_motion_its_pull_and_the_next_plans_cap():
    stage = PlannerStage(paper_scene(), _params())
    home_cap = stage.planner.pull_limit
    assert home_cap is not None and 5.0 < home_cap < 60.0
    R = 0.025 * np.sqrt(2.0)
    plan = None
    for i in range(5):                                           # a finger on the cylinder's top, 48 Hz
        t = i / 48.0
        plan, _ = stage.plan(t, t, np.array([-R + R * np.cos(0.3), 0.0, R * np.sin(0.3)]))
    assert plan is not None and plan.touching
    cmd = stage.command(plan, 5 / 48.0, lambda size: None)
    stage.cap_pull()                                             # the next plans' cap, once it is sent
    Tl, Tr = plan.clamp_matrices()
    np.testing.assert_allclose(cmd.left, Tl)
    np.testing.assert_allclose(cmd.right, Tr)
    assert cmd.pull == pytest.approx(clamp_force(plan.stretch, stage.planner.cfg.material))
    cfg = stage.planner.cfg
    guard = PullGuard({"left": cfg.reach.left_base, "right": cfg.reach.right_base}, 0.9)
    assert stage.planner.pull_limit == pytest.approx(guard.limit(Tl, Tr), rel=1e-3)
    seg = SheetSegment.from_fields(SimpleNamespace(**cmd.motion))
    o, _, strain = seg.goal_pose()
    np.testing.assert_allclose(o, plan.origin, atol=1e-9)       # the motion ends at the plan
    assert strain == pytest.approx(plan.stretch, abs=1e-9)
