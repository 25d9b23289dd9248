"""Every node takes the same scene, planner and world side: the scripted finger follows the scene's
stroke path, the planner presents the scene's tangent plane, the sheet's tension follows the scene's
compliance (the organ's tumour), and the paper's cylinder as a scene gives the same finger and Table I.

References are closed forms from the scene files' numbers (sphere centre and radius, Hertz), never the
scene code's own answers."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
import yaml

from flexsheet.model.scenes import SCENES_DIR, load_scene, paper_scene
from flexsheet.planning.compliance import SceneCompliance, energy_share, eshelby_factor
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.shape import SmoothMeshShape, planner_shape
from flexsheet.planning.surface_planner import SurfacePlanner
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.finger import FingerScript
from messages import Fingertip, Header, ObjectDeformation
from messages import topics as T
from nodes.planner.node import PlannerNode, PlannerParams
from nodes.world.node import WorldNode, WorldParams

SPHERE = SCENES_DIR / "sphere.yaml"
ORGAN = SCENES_DIR / "organ.yaml"


def _sphere_numbers() -> tuple[np.ndarray, float]:
    """The sphere's centre and radius as the file states them (not through the scene code)."""
    d = yaml.safe_load(SPHERE.read_text())
    return np.asarray(d["object"]["pose"]["position"], float), float(d["object"]["radius"])


# ---------------------------------------------------------------------------------------------- world finger
def test_finger_follows_the_sphere_path_at_its_depth():
    c, R = _sphere_numbers()
    sc = load_scene(SPHERE)
    f = FingerScript(scene=sc, tremor_rms=0.0, wander_deg=0.0, wander_axial=0.0, lag=0.0, depth=0.001)
    t = np.linspace(f.t_move, f.t_move + f.moving_time, 200)
    P = f.positions(t)
    assert np.linalg.norm(P - c, axis=1) == pytest.approx(R - 0.001, abs=1e-6)   # p − depth·n on the sphere
    # the arc 0° → 60° toward +z in the y = 0 plane (sphere.yaml's stroke), monotone
    ang = np.degrees(np.arctan2(P[:, 2] - c[2], P[:, 0] - c[0]))
    assert (np.abs(P[:, 1]).max() < 1e-9 and ang[0] == pytest.approx(0.0, abs=1e-6)
            and ang[-1] == pytest.approx(60.0, abs=1e-4))
    assert np.all(np.diff(ang) >= -1e-9)
    # approach from 30 mm outside along the normal at the start
    assert np.linalg.norm(f.position(0.0) - c) == pytest.approx(R + f.approach_distance - 0.001, abs=1e-6)
    # a push presses at the path's start, to push_depth
    push = FingerScript(scene=sc, mode="push", push_depth=0.008, tremor_rms=0.0, wander_deg=0.0,
                        wander_axial=0.0)
    mid = push.t_move + push.moving_time / 2
    assert np.linalg.norm(push.position(mid) - c) == pytest.approx(R - 0.008, abs=1e-6)
    # with the human's noise the finger stays within a millimetre of the path's depth
    noisy = FingerScript(scene=sc, seed=3).positions(t)
    assert np.abs(np.linalg.norm(noisy - c, axis=1) - (R - 0.0005)).max() < 1e-3


def test_cylinder_scene_gives_the_cylinder_finger():
    """The path-following finger on the paper's cylinder is the cylinder-parameter finger (to 10 nm)."""
    t = np.linspace(0.0, 15.0, 1500)
    for kw in ({}, {"mode": "stroke_push", "push_depth": 0.01, "seed": 2}, {"mode": "push", "seed": 5},
               {"profile": "minjerk", "moving_time": 30.0}):
        a = FingerScript(**kw).positions(t)
        for sc in (paper_scene(), load_scene(SCENES_DIR / "cylinder.yaml")):
            assert np.abs(FingerScript(scene=sc, **kw).positions(t) - a).max() < 1e-8, kw


def test_world_node_plays_the_scene_path(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))
    c, R = _sphere_numbers()

    async def scenario():
        params = {"start_delay": 0.0, "scene": str(SPHERE), "rate_hz": 200.0,
                  "script": [{"mode": "stroke", "moving_time": 1.0, "approach_time": 0.2, "hold_before": 0.1,
                              "tremor_rms": 0.0, "wander_deg": 0.0, "wander_axial": 0.0, "lag": 0.0}],
                  "twin": {"realism": "ideal"}}
        async with NodeHarness(WorldNode, params=params) as h:
            msgs = await h.wait_for(T.FINGER_TRUTH, n=200, timeout=6.0)
        moving = [m for m in msgs if m.phase == "stroke"]
        assert len(moving) > 50
        r = [np.linalg.norm(m.position - c) for m in moving]
        assert r == pytest.approx([R - 0.0005] * len(r), abs=1e-6)
        assert max(math.degrees(m.target_angle) for m in moving) > 30.0
    asyncio.run(scenario())
    with pytest.raises(ValueError, match="scene"):
        WorldParams(scene=str(tmp_path / "missing.yaml"))


# ---------------------------------------------------------------------------------------------- planner
def test_planner_on_the_sphere_is_tangent_to_it():
    """Along a 10 s stroke the contact lies on the sphere, the sheet is tangent there (§V-A on a sphere: the
    ray from the centre), and the contact stays within 0.5 mm of the finger's own ray point (the pose
    filter's transient: it takes the finger's tremor out of the sheet's pose)."""
    c, R = _sphere_numbers()
    sc = load_scene(SPHERE)
    f = FingerScript(scene=sc, seed=1, moving_time=10.0)
    pl = SurfacePlanner(planner_shape(sc), PlannerConfig(), SceneCompliance(sc))
    worst = 0.0
    for t in np.arange(0.0, f.duration, 1.0 / 48.0):
        p = f.position(t)
        plan = pl.update(t, p)
        con = np.asarray(plan.contact)
        n_true = (p - c) / np.linalg.norm(p - c)
        n_con = (con - c) / np.linalg.norm(con - c)
        assert np.linalg.norm(con - c) == pytest.approx(R, abs=1e-9)
        assert np.linalg.norm(con - (c + R * n_true)) < 5e-4
        if "rate_limited" not in plan.status:
            worst = max(worst, math.degrees(math.acos(min(1.0, float(np.dot(plan.normal, n_con))))))
    assert worst < 1e-5
    assert plan.touching and plan.k_source == "scene"


def test_planner_node_takes_the_scene_and_its_compliance():
    c, R = _sphere_numbers()
    r_f, E, nu = 0.008, 10e3, 0.45             # sphere.yaml: finger and material
    p = c + (R + 0.0002) * np.array([math.cos(0.3), 0.0, math.sin(0.3)])   # 0.2 mm off the surface

    async def scenario():
        async with NodeHarness(PlannerNode, params={"scene": str(SPHERE), "stiffness_tau": 0.0}) as h:
            now = h.node.now()
            h.inject(T.FINGERTIP, Fingertip(header=Header(stamp=now), position=p, covariance=np.eye(3) * 1e-8,
                                            valid=True, predicted_position=p, exposure_stamp=now - 0.01))
            st = (await h.wait_for(T.SHEET_TARGET, n=1, timeout=3.0))[0]
            # FEM stiffness for a cylinder: not this scene's, so not used
            h.inject(T.DEFORMATION, ObjectDeformation(
                header=Header(stamp=now), vertices=np.zeros((3, 3), np.float32),
                faces=np.array([[0, 1, 2]], np.int32),
                contact_force=0.1, stiffness=12.0, depth=0.001, contact_point=np.zeros(3),
                method="condensed"))
            await asyncio.sleep(0.1)
            h.inject(T.FINGERTIP,
                     Fingertip(header=Header(stamp=now + 0.02), position=p, covariance=np.eye(3) * 1e-8,
                               valid=True, predicted_position=p, exposure_stamp=now + 0.01))
            st2 = (await h.wait_for(T.SHEET_TARGET, n=2, timeout=3.0))[1]
            hb = h.node.heartbeat()
        return st, st2, hb

    st, st2, hb = asyncio.run(scenario())
    n_true = (p - c) / np.linalg.norm(p - c)
    assert np.asarray(st.normal) == pytest.approx(n_true, abs=1e-9)
    assert np.asarray(st.contact_point) == pytest.approx(c + R * n_true, abs=1e-9)
    # Hertz at the light-touch depth 0.5 mm: k = 2 E/(1−ν²) √(R_e d), 1/R_e = 1/r_f + 1/R (sphere on sphere)
    R_e = 1.0 / (1.0 / r_f + 1.0 / R)
    k = 2.0 * E / (1.0 - nu ** 2) * math.sqrt(R_e * 0.0005)
    assert st.object_stiffness == pytest.approx(k, rel=2e-3)
    assert st.tension > 0.0 and st.stiffness > 0.0
    assert st2.object_stiffness == pytest.approx(k, rel=2e-3)          # the cylinder FEM's 12 N/m is ignored
    assert "scene's estimate" in hb.message and "another object" in hb.message
    with pytest.raises(ValueError, match="scene"):
        PlannerParams(scene="launch/scenes/nope.yaml")


def test_planner_uses_the_fem_stiffness_on_the_paper_cylinder():
    async def scenario():
        async with NodeHarness(PlannerNode, params={"scene": str(SCENES_DIR / "cylinder.yaml")}) as h:
            now = h.node.now()
            h.inject(T.DEFORMATION, ObjectDeformation(
                header=Header(stamp=now), vertices=np.zeros((3, 3), np.float32),
                faces=np.array([[0, 1, 2]], np.int32),
                contact_force=0.1, stiffness=12.0, depth=0.001, contact_point=np.zeros(3),
                method="condensed"))
            await asyncio.sleep(0.1)
            p = np.array([0.001, 0.0, 0.0])
            h.inject(T.FINGERTIP, Fingertip(header=Header(stamp=now), position=p, covariance=np.eye(3) * 1e-8,
                                            valid=True, predicted_position=p, exposure_stamp=now - 0.01))
            return (await h.wait_for(T.SHEET_TARGET, n=1, timeout=3.0))[0], h.node.heartbeat()

    st, hb = asyncio.run(scenario())
    assert st.object_stiffness == 12.0 and st.stiffness == pytest.approx(12.0, rel=1e-6)
    assert "FEM" in hb.message


# ---------------------------------------------------------------------------------------------- compliance
def test_hertz_estimate_matches_closed_forms():
    """Cylinder (R 25√2 mm) and rounded box face: the estimate is Hertz's 2E*√(R_e d) with the curvature the
    estimator measures numerically from the normals, against the closed-form radii."""
    r_f, nu = 0.008, 0.45
    cyl = load_scene(SCENES_DIR / "cylinder.yaml")
    R = 0.025 * math.sqrt(2.0)
    q, n = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    e = SceneCompliance(cyl).estimate(q, n, 0.002)
    R_e = math.sqrt(1.0 / (1.0 / r_f + 1.0 / R) * r_f)           # Johnson §4.2: √(R′R″)
    assert e.kappa == pytest.approx((1.0 / R, 0.0), abs=1e-6)
    assert e.k == pytest.approx(2.0 * 10e3 / (1 - nu ** 2) * math.sqrt(R_e * 0.002), rel=1e-4)
    box = load_scene(SCENES_DIR / "rounded_box.yaml")            # E 20 kPa, front face flat
    e = SceneCompliance(box).estimate(q, n, 0.001)
    assert e.k == pytest.approx(2.0 * 20e3 / (1 - nu ** 2) * math.sqrt(r_f * 0.001), rel=1e-6)
    # below the light-touch depth the estimate takes that depth; deeper pushes are stiffer (√d)
    C = SceneCompliance(cyl)
    assert (C(q, n, 0.0) == C(q, n, 0.0005)
            and C(q, n, 0.008) == pytest.approx(4.0 * C(q, n, 0.0005), rel=1e-9))
    with pytest.raises(ValueError, match="finite"):
        C(q, n, float("nan"))


def test_energy_share_and_eshelby_factor():
    q, n = np.zeros(3), np.array([1.0, 0.0, 0.0])
    # a small ball far below: share ∝ cos²θ / r⁴ (Boussinesq, ν = ½) — doubling the distance: 1/16
    w1 = energy_share(q, n, 0.002, (-0.02, 0.0, 0.0), 0.002)
    w2 = energy_share(q, n, 0.002, (-0.04, 0.0, 0.0), 0.002)
    assert (w1 / w2
            == pytest.approx(16.0 * ((0.04 ** 2 + 0.002 ** 2) / (0.02 ** 2 + 0.002 ** 2) / 4.0) ** 2,
                             rel=0.02))
    # and at 45° off the axis: cos² = ½ of straight below at the same distance
    w45 = energy_share(q, n, 0.002, (-0.02 / math.sqrt(2), 0.02 / math.sqrt(2), 0.0), 0.002)
    assert w45 / w1 == pytest.approx(0.5, rel=0.02)
    assert energy_share(q, n, 0.002, (0.02, 0.0, 0.0), 0.005) == 0.0      # above the tangent plane: no share
    assert eshelby_factor(1.0) == 0.0 and eshelby_factor(1e12) == pytest.approx(2.5)
    assert eshelby_factor(1e-12) == pytest.approx(-5.0 / 3.0)
    with pytest.raises(ValueError):
        energy_share(q, n, 0.0, (-0.02, 0.0, 0.0), 0.002)


def test_organ_stiffness_along_the_path_peaks_over_the_tumour():
    sc = load_scene(ORGAN)
    d = yaml.safe_load(ORGAN.read_text())["inclusions"][0]
    center = np.asarray(d["center"], float)
    P, N = sc.stroke_points(81)
    i_inc = int(np.argmin(np.linalg.norm(P - center, axis=1)))      # the path point over the tumour
    step = sc.stroke_length() / 80
    C = SceneCompliance(sc)
    for depth in (0.0005, 0.005):
        est = [C.estimate(p, n, depth) for p, n in zip(P, N, strict=True)]
        k = np.array([e.k for e in est])
        contrast = k / np.array([e.k_body for e in est])
        assert abs(int(np.argmax(k)) - i_inc) * step < 0.004, depth  # the stiffest point: over the tumour
        assert abs(int(np.argmax(contrast)) - i_inc) * step < 0.002
        assert contrast[i_inc] > 1.05 and contrast[0] < 1.005               # 10x stiffer tumour 8.6 mm down
        assert k[i_inc] > 1.04 * np.median(k)


# ---------------------------------------------------------------------------------------------- meshes
def test_organ_planner_normals_are_smooth_and_local_support_finds_the_contact():
    sc = load_scene(ORGAN)
    shape = planner_shape(sc)
    assert isinstance(shape, SmoothMeshShape) and planner_shape(sc) is shape
    P, N = sc.stroke_points(200)
    normals = np.array([shape.closest(tuple(p + 0.003 * n))[1] for p, n in zip(P, N, strict=True)])
    steps = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals[1:], normals[:-1]), -1, 1)))
    faces = np.array([sc.shape().closest(tuple(p + 0.003 * n))[1] for p, n in zip(P, N, strict=True)])
    fsteps = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", faces[1:], faces[:-1]), -1, 1)))
    assert steps.max() < 1.0 < fsteps.max()          # face normals jump between facets; the planner's do not
    q = P[100]
    assert np.linalg.norm(np.asarray(shape.support(tuple(N[100]), tuple(q))) - q) < 2e-4
    d = shape.closest(tuple(q - 0.004 * N[100]))[2]
    assert d == pytest.approx(-0.004, abs=3e-4)                           # inside: negative distance


def test_organ_batched_queries_give_the_one_at_a_time_answers():
    """The report's batched closest points and supports (``closest_many``, ``support_many``) on the organ
    equal the per-sample queries, inside and outside, for tilted planes near the stroke."""
    shape = planner_shape(load_scene(ORGAN))
    rng = np.random.default_rng(7)
    P, N = load_scene(ORGAN).stroke_points(40)
    x = P + N * rng.uniform(-0.004, 0.004, (len(P), 1))
    q, n, d = shape.closest_many(x)
    one = [shape.closest(tuple(p)) for p in x]
    assert (np.abs(q - np.array([o[0] for o in one])).max() < 1e-12
            and np.abs(n - np.array([o[1] for o in one])).max() < 1e-12)
    assert np.abs(d - np.array([o[2] for o in one])).max() < 1e-12 and (d < 0).any() and (d > 0).any()
    tilt = N + rng.normal(0.0, 0.08, N.shape)
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    s = shape.support_many(tilt, P)
    assert (np.abs(s
                   - np.array([shape.support(tuple(t), tuple(p)) for t,
                               p in zip(tilt, P, strict=True)])).max() < 1e-9)
    assert np.abs(s - P).max() > 1e-3                                   # the tilted planes touch elsewhere


# ---------------------------------------------------------------------------------------------- Table I
def test_cylinder_scene_reproduces_the_table1_rows():
    """The in-process stroke on the paper's cylinder as a scene (path-following finger, section along the
    scene's stroke) gives the cylinder's Table I row (axis cross-section) of before."""
    from flexsheet.analysis.table1 import scene_table1_row, table1_row
    from flexsheet.experiments import stroke_model as st
    from flexsheet.model.shapes import paper_cylinder

    tw = st.make_twin("realistic", 0, None)
    old = st.simulate(10.0, tw, None, 0)
    new = st.simulate(10.0, tw, None, 0, scene=load_scene(SCENES_DIR / "cylinder.yaml"))
    # the two fingers differ by < 10 nm (test above), but the closed loop (rate limits, IK seeds, servo
    # limits) is chaotic: a 5 nm change of the tremor's amplitude alone moves this row's Δθ by 0.6 %
    for k in ("dtheta_mean_deg", "dtheta_std_deg", "dd_mean_mm", "dd_2r_mean_mm", "gap_mean_mm"):
        assert new[k] == pytest.approx(old[k], rel=0.015), k
    assert new["n"] == old["n"]
    rng = np.random.default_rng(0)
    ang = np.radians(np.linspace(0, 60, 50))
    R = 0.025 * math.sqrt(2.0)
    D = np.column_stack([-R + (R + 0.001) * np.cos(ang), rng.normal(0, 0.003, 50), (R + 0.001) * np.sin(ang)])
    b = ang - 0.01
    nrm = np.column_stack([np.cos(b), rng.normal(0, 0.02, 50), np.sin(b)])     # tilted about the axis too
    org = np.column_stack([-R + R * np.cos(b), np.zeros(50), R * np.sin(b)])
    a, c = table1_row(paper_cylinder(), D, org, nrm), scene_table1_row(paper_scene(), D, org, nrm)
    assert all(a[k] == pytest.approx(c[k], rel=1e-9, abs=1e-12) for k in a)
    assert a["dtheta_mean_deg"] == pytest.approx(math.degrees(0.01), rel=1e-6)
