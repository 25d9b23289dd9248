"""Planner node through the in-process harness, the experiment CLI (quick) and the bench CLI."""

import asyncio
import time

import numpy as np
import pytest

from flexsheet.runtime.testing import NodeHarness
from messages import Fingertip, Header, ObjectDeformation, topics
from nodes.planner.node import PlannerNode, PlannerParams


def _ft(p, valid=True, stamp=None, pred=None):
    s = time.time() if stamp is None else stamp
    p = np.asarray(p, float)
    return Fingertip(header=Header(stamp=s), position=p, covariance=np.eye(3) * 1e-8, valid=valid,
                     predicted_position=np.asarray(pred if pred is not None else p, float),
                     prediction_horizon=0.03 if pred is not None else 0.0, exposure_stamp=s - 0.012)


def test_node_publishes_targets_with_source_stamp_and_holds_on_lost_marker():
    async def scenario():
        async with NodeHarness(PlannerNode, params={"object_stiffness": 20.0,
                                                    "stiffness_from_scene": False}) as h:
            m = _ft([0.02, 0.0, 0.0])
            h.inject(topics.FINGERTIP, m)
            st = (await h.wait_for(topics.SHEET_TARGET, n=1, timeout=2.0))[0]
            left = (await h.wait_for(topics.ARM_LEFT_TARGET, n=1, timeout=2.0))[0]
            right = (await h.wait_for(topics.ARM_RIGHT_TARGET, n=1, timeout=2.0))[0]
            assert st.status == "ok" and st.source_stamp == m.exposure_stamp
            assert np.allclose(st.sheet_origin, 0.0) and np.allclose(st.normal, [1, 0, 0])
            assert st.stiffness == pytest.approx(20.0, rel=1e-6)
            half = 0.12 * (1 + st.stretch)
            assert (np.allclose(left.pose[:3, 3], [0, half, 0])
                    and np.allclose(right.pose[:3, 3], [0, -half, 0]))
            assert left.source_stamp == m.exposure_stamp and right.arm == "right"
            h.inject(topics.FINGERTIP, _ft([0.0, 0.0, 0.0], valid=False, stamp=m.header.stamp + 0.02))
            out = await h.wait_for(topics.SHEET_TARGET, n=2, timeout=2.0)
            assert (out[1].status == "hold:marker_lost"
                    and np.array_equal(out[1].sheet_origin, st.sheet_origin))
            h.inject_raw(topics.FINGERTIP, [b"garbage"])
            await asyncio.sleep(0.1)
            assert h.rejected(topics.FINGERTIP) == 1
    asyncio.run(scenario())


def test_node_uses_fem_stiffness_and_prediction():
    async def scenario():
        async with NodeHarness(PlannerNode, params={"use_prediction": True}) as h:
            dm = ObjectDeformation(header=Header(stamp=time.time()), vertices=np.zeros((3, 3), np.float32),
                                   faces=np.array([[0, 1, 2]], np.int32), contact_force=0.1, stiffness=12.0,
                                   depth=0.001, contact_point=np.zeros(3), method="condensed")
            h.inject(topics.DEFORMATION, dm)
            await asyncio.sleep(0.1)
            h.inject(topics.FINGERTIP, _ft([0.02, 0.0, 0.0], pred=[0.02, 0.01, 0.0]))
            st = (await h.wait_for(topics.SHEET_TARGET, n=1, timeout=2.0))[0]
            assert st.object_stiffness == 12.0 and st.stiffness == pytest.approx(12.0, rel=1e-6)
            assert st.contact_point[1] == pytest.approx(0.01)          # planned on the predicted position
    asyncio.run(scenario())


def test_params_validate():
    with pytest.raises(ValueError):
        PlannerParams(shape="box")          # the old bare shape: scenes name shapes now
    with pytest.raises(ValueError):
        PlannerParams(bogus=1)
    cfg = PlannerParams(max_stretch=0.2, reach_max=0.5).planner_config()
    assert cfg.material.max_stretch == 0.2 and cfg.reach.reach_max == 0.5


@pytest.mark.parametrize("lam, tol", [(0.1, 0.005), (1.0, 0.01)])
def test_experiment_kf_tuning_is_kalatas_alpha_beta_in_steady_state(lam, tol):
    """The stroke experiment runs the triangulator's real Kalman filter with q from a tracking index λ; its
    steady-state gains must be Kalata's closed-form α-β gains for that λ (IEEE T-AES 20(2), 1984)."""
    from flexsheet.vision.predict import Predictor, q_for_tracking_index

    T, sig = 1.0 / 48.0, 1e-4
    pr = Predictor(q_for_tracking_index(lam, sig, T))
    R = sig ** 2 * np.eye(3)
    for k in range(2000):
        pr.update(k * T, np.zeros(3), R)
    before = pr.predict(T)                                   # prediction for the next sample
    pr.update(2000 * T, before + [1e-5, 0.0, 0.0], R)        # a 10 µm innovation along x
    alpha = (pr.kf.x[0] - before[0]) / 1e-5
    beta = (pr.kf.velocity[0] - 0.0) * T / 1e-5
    r = (4.0 + lam - np.sqrt(8.0 * lam + lam * lam)) / 4.0   # Kalata: λ = 1 → α = 0.75, β = 0.5
    a_k = 1.0 - r * r
    b_k = 2.0 * (2.0 - a_k) - 4.0 * np.sqrt(1.0 - a_k)
    assert alpha == pytest.approx(a_k, abs=tol) and beta == pytest.approx(b_k, abs=tol)
    with pytest.raises(ValueError, match="tracking_index"):
        q_for_tracking_index(0.0, sig, T)


def test_params_are_the_pure_configs_fields():
    from dataclasses import fields

    from flexsheet.model.motion_limits import MotionLimits
    from flexsheet.model.tension import SheetMaterial
    from flexsheet.planning.limits import ReachModel
    from flexsheet.planning.planner_config import PlannerConfig

    names = set(PlannerParams.model_fields)
    for cls in (PlannerConfig, SheetMaterial, MotionLimits, ReachModel):
        for f in fields(cls):
            if f.name not in ("material", "limits", "reach"):
                assert ("sheet_size" if f.name == "size" else f.name) in names, f.name
    # the default params give exactly the default config; a bad value fails at validation, naming the field
    assert PlannerParams().planner_config() == PlannerConfig()
    with pytest.raises(ValueError, match="release_distance"):
        PlannerParams(touch_distance=0.01, release_distance=0.005)
    with pytest.raises(ValueError, match="v_max"):
        PlannerParams(v_max=0.0)


def test_bench_prints_json(capsys):
    from flexsheet.benches import planner as bench

    r = bench.measure("cylinder", 50)
    assert r["update_median_us"] > 0 and r["n"] == 50


def test_reach_takes_the_arm_bases_from_display_calib(tmp_path):
    """The planner (an estimator) takes the arm bases of the registered display, never the twin's truth."""
    from flexsheet.calibration.display_calib import nominal_display_calib
    from flexsheet.calibration.display_calib_file import write_display_calib
    from flexsheet.model.geometry import LEFT_BASE

    dc = nominal_display_calib()
    dc.arms["left"].T_display_base[:3, 3] += (0.004, -0.002, 0.001)
    path = tmp_path / "display.yaml"
    write_display_calib(str(path), dc)
    reach = PlannerParams(display_calib=str(path)).planner_config().reach
    assert (reach.left_base[:3]
            == pytest.approx((LEFT_BASE[0] + 0.004, LEFT_BASE[1] - 0.002, LEFT_BASE[2] + 0.001)))
    assert reach.left_base[3] == pytest.approx(LEFT_BASE[3])
    assert PlannerParams().planner_config().reach.left_base == LEFT_BASE     # no file: the design bases
    with pytest.raises(ValueError, match="not found"):
        PlannerParams(display_calib=str(tmp_path / "missing.yaml"))
    del dc.arms["right"]
    write_display_calib(str(path), dc)
    with pytest.raises(ValueError, match="arms.right"):
        PlannerParams(display_calib=str(path))


def test_the_pull_is_capped_at_the_targets_and_the_targets_carry_it():
    """The clamp force is capped at pull_margin × the torque-limited pull at the targets the planner sends
    (flexsheet.planning.pull_guard; 33.5 N at home, set by J3), and each ArmTarget carries the planned pull,
    which never passes the arms' limit at that target."""
    from flexsheet.arm.kinematics import ArmKinematics, home_joints
    from flexsheet.arm.pull_limit import max_pull
    from flexsheet.model.geometry import LEFT_BASE
    from flexsheet.model.tension import SheetMaterial, clamp_force

    async def scenario():
        async with NodeHarness(PlannerNode, params={"object_stiffness": 900.0,
                                                    "stiffness_from_scene": False}) as h:
            home = max_pull(ArmKinematics("left", LEFT_BASE), home_joints("left"))[0]
            assert (h.node.stage.planner.pull_limit == pytest.approx(0.9 * home, rel=0.02)
                    and 0.9 * home < 40.0)
            t0 = time.time()
            for k in range(5):
                h.inject(topics.FINGERTIP, _ft([0.02 * np.cos(0.1 * k), 0.02 * np.sin(0.1 * k), 0.0],
                                               stamp=t0 + 0.02 * k))
                await h.wait_for(topics.SHEET_TARGET, n=k + 1, timeout=2.0)   # one at a time: the latest-only
            sts = await h.wait_for(topics.SHEET_TARGET, n=5, timeout=2.0)      # QoS may drop a queued one
            lefts = await h.wait_for(topics.ARM_LEFT_TARGET, n=5, timeout=2.0)
            kin = ArmKinematics("left", LEFT_BASE)
            for st, left in zip(sts, lefts, strict=True):
                assert "object_stiffer_than_sheet" in st.status
                assert left.pull == pytest.approx(clamp_force(st.stretch, SheetMaterial()), rel=1e-9)
                q = kin.ik(left.pose, home_joints("left")).q
                assert left.pull <= max_pull(kin, q)[0]          # the bridge takes it
    asyncio.run(scenario())


def test_with_the_task_mark_the_away_sheet_waits_tangent_at_the_mark_offset_outside():
    """A finger 30 mm in front of the home sheet, 20 mm up: without /task/mark the sheet stands on the object
    under it; with the mark at the cylinder's front it waits there, tangent, 3 mm outside; a malformed mark is
    refused and counted."""
    from flexsheet.model.shapes import paper_cylinder
    from messages import TaskMark

    cyl = paper_cylinder()

    async def scenario():
        async with NodeHarness(PlannerNode, params={"object_stiffness": 20.0, "stiffness_from_scene": False,
                                                    "psi_range": 0.0, "use_mark": True}) as h:
            s = time.time()
            finger = [0.03, 0.0, 0.02]
            h.inject(topics.FINGERTIP, _ft(finger, stamp=s))
            first = (await h.wait_for(topics.SHEET_TARGET, n=1, timeout=2.0))[0]
            proj = cyl.project(tuple(finger))
            assert np.allclose(first.contact_point, proj.point, atol=1e-9)       # no mark: under the finger
            h.inject(topics.TASK_MARK, TaskMark(header=Header(stamp=s), point=np.zeros(3),
                                                normal=np.array([1.0, 0.0, 0.0])))
            await asyncio.sleep(0.1)
            for k in range(1, 40):                  # 0.8 s: within the mark's mark_timeout (1 s)
                h.inject(topics.FINGERTIP, _ft(finger, stamp=s + k * 0.02))
                out = await h.wait_for(topics.SHEET_TARGET, n=k + 1, timeout=2.0)
            last = out[-1]
            assert not last.touching and np.allclose(last.normal, [1.0, 0.0, 0.0], atol=1e-6)
            assert np.allclose(last.contact_point, 0.0, atol=1e-6)
            assert np.allclose(last.sheet_origin, [0.003, 0.0, 0.0], atol=1e-6)   # 3 mm outside the front
            h.inject(topics.TASK_MARK, TaskMark(header=Header(stamp=s + 1.3), point=np.zeros(3),
                                                normal=np.zeros(3)))
            await asyncio.sleep(0.1)
            assert h.rejected(topics.TASK_MARK) == 1
    asyncio.run(scenario())
