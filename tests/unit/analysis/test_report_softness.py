"""What the finger feels against what the object asks (flexsheet.analysis.report_softness): the true sheet's
force over the object's, from a bag."""

import numpy as np
import pytest

from flexsheet.analysis.report_softness import felt_force
from messages import ContactTruth, Header, ObjectDeformation, SheetState


def _sheet(t: float, depth: float, force: float) -> ContactTruth:
    return ContactTruth(header=Header(stamp=t), touching=True, depth=depth, force=force, point=np.zeros(3),
                        stiffness=force / depth)


def _deformation(t: float, force: float) -> ObjectDeformation:
    return ObjectDeformation(header=Header(stamp=t + 0.004), vertices=np.zeros((3, 3), np.float32),
                             faces=np.array([[0, 1, 2]], dtype=np.int32), contact_force=force,
                             stiffness=100.0,
                             depth=0.01, contact_point=np.zeros(3), method="linear", source_stamp=t)


def _bag(felt_per_mm: float, object_per_mm: float, n: int = 100) -> dict:
    """A press to 10 mm: the sheet at 50 Hz, the object's force at 48 Hz from fingertips exposed 5 ms
    earlier."""
    sheet, defs = [], []
    for k in range(n):
        t = 1.0 + k * 0.02
        depth = 0.001 + 0.009 * k / (n - 1)                     # 1 -> 10 mm: the first ones below 2 mm
        sheet.append((t, _sheet(t, depth, felt_per_mm * depth * 1e3)))
    for k in range(int(n * 0.02 * 48)):
        t = 1.0 - 0.005 + k / 48.0
        depth = 0.001 + 0.009 * min(max((t + 0.005 - 1.0) / (0.02 * (n - 1)), 0.0), 1.0)
        defs.append((t, _deformation(t, object_per_mm * depth * 1e3)))
    return {"/world/contact": sheet, "/object/deformation": defs}


def test_a_sheet_as_stiff_as_the_object_is_within_the_weber_fraction_and_a_softer_one_is_not():
    same = felt_force(_bag(0.10, 0.10))
    assert same["n"] > 70 and same["verdict"] == "met"
    assert same["ratio"]["median"] == pytest.approx(1.0, abs=0.05)  # the 48 Hz object lags the sheet a little
    assert same["within_15pct"] > 0.9
    assert same["felt_stiffness_n_per_m"] == pytest.approx(100.0, rel=1e-6)
    soft = felt_force(_bag(0.07, 0.10))                          # 30 % softer than asked: noticeable
    assert soft["verdict"] == "MISSED" and soft["ratio"]["median"] == pytest.approx(0.7, abs=0.04)
    assert soft["within_15pct"] < 0.1
    # a stiffness_scale of 0.7 (the planner's, from the run's start) asks for that softer sheet
    assert felt_force(_bag(0.07, 0.10), scales=[(0.0, 0.7)])["verdict"] == "met"
    # a scale set mid-press applies from then on only: half the samples judged at 0.7, half at 1
    half = felt_force(_bag(0.07, 0.10), scales=[(0.0, 1.0), (2.0, 0.7)])
    assert 0.4 < half["within_15pct"] < 0.6


def test_no_press_no_object_force_or_a_bad_scale():
    bag = _bag(0.1, 0.1)
    assert felt_force({"/world/contact": bag["/world/contact"]}) == {}
    assert felt_force({**bag,
                       "/world/contact": [(t, _sheet(t, 0.001, 0.1)) for t,
                                          _ in bag["/world/contact"]]}) == {}
    with pytest.raises(ValueError, match="scale"):
        felt_force(bag, scales=[(0.0, 0.0)])


def _table_msg(c_body: float = 1000.0, c_top: float = 1000.0):
    """A force-depth table along +z: F = c·d^1.5, the points from z = 0 to 40 mm, the one at 20 mm c_top."""
    from messages import ObjectForceDepth

    z = np.linspace(0.0, 0.04, 9)
    depths = np.linspace(0.0, 0.02, 41)
    c = np.where(np.isclose(z, 0.02), c_top, c_body)
    return ObjectForceDepth(header=Header(stamp=0.5), points=np.stack([np.zeros(9), np.zeros(9), z], 1),
                            normals=np.tile([1.0, 0.0, 0.0], (9, 1)),
                            names=["reference"] + [f"p{i}" for i in range(8)],
                            depths=depths, force=c[:, None] * depths[None, :] ** 1.5, scene_key="k")


def _contact(t: float, z: float, depth: float, force: float) -> ContactTruth:
    """A contact at height z on the table's face (x = 0, normal +x): its point the dent's bottom, x =
    −depth."""
    return ContactTruth(header=Header(stamp=t), touching=True, depth=depth, force=force,
                        point=np.array([-depth, 0.0, z]), stiffness=1.0)


def test_with_the_objects_table_the_request_is_its_force_at_the_true_depth():
    contacts = []
    for k in range(200):
        t = 1.0 + 0.02 * k
        depth = 0.002 + 0.008 * (k % 50) / 49
        felt = 0.5 * 1000.0 * depth ** 1.5 * (1.1 if k % 4 == 0 else 1.0)      # a quarter 10 % stiff: within
        contacts.append((t, _contact(t, 0.0, depth, felt)))
    d = {"/world/contact": contacts, "/object/force_depth": [(0.5, _table_msg())]}
    r = felt_force(d, scales=[(0.0, 0.5)])
    assert r["basis"] == "force_depth" and r["n"] == 200
    assert (r["ratio"]["median"] == pytest.approx(1.0, abs=2e-3) and r["within_15pct"] == 1.0
            and r["verdict"] == "met")
    r2 = felt_force(d, scales=[(0.0, 0.4)])  # a sheet 25 % stiffer than asked
    assert r2["within_15pct"] == 0.0 and r2["verdict"] == "MISSED"


def test_the_inclusion_contrast_is_felt_from_true_forces_at_matched_depth():
    from flexsheet.analysis.report_softness import inclusion_contrast
    from flexsheet.model.scenes import load_scene

    class _Scene:  # the organ's inclusion, moved onto +z
        inclusions = [type("I", (), {"center": (-0.007, 0.0, 0.02), "radius": 0.007})()]

    contacts = []
    for k in range(300):
        t = 1.0 + 0.02 * k
        z = 0.04 * (k % 100) / 99
        depth = 0.003 + 0.006 * ((k // 100) % 3) / 2
        felt = (1300.0 if abs(z - 0.02) <= 0.007 else 1000.0) * depth ** 1.5    # 30 % over the footprint
        contacts.append((t, _contact(t, z, depth, felt)))
    d = {"/world/contact": contacts, "/object/force_depth": [(0.5, _table_msg(1000.0, 1250.0))]}
    ic = inclusion_contrast(d, _Scene())
    assert ic["felt"] == pytest.approx(0.30, abs=1e-6) and len(ic["bins"]) == 3
    assert 0.0 < ic["requested"] < 0.25 and ic["mapped"] == pytest.approx(ic["requested"], abs=1e-9)
    assert inclusion_contrast(d, load_scene("launch/scenes/sphere.yaml")) == {}        # no inclusion: nothing


def test_the_sheet_summary_counts_one_arm_holding_per_cycle_and_the_strain_over_the_plan():
    from flexsheet.analysis.report_softness import sheet_summary
    from messages import ArmJointState, SheetState, SheetTarget

    def js(t, arm, status):
        return (t, ArmJointState(header=Header(stamp=t), arm=arm, position=np.zeros(6), velocity=np.zeros(6),
                                 commanded=np.zeros(6), executing=np.zeros(6), pose=np.eye(4), status=0,
                                 bridge_status=status))

    states = [js(1.0, a, "hold:no_target") for a in ("left", "right")]
    states += [js(1.0 + 0.01 * k, a, "hold:limit:J3" if (a == "left" and 5 <= k < 8) else "ok")
               for k in range(1, 20) for a in ("left", "right")]
    sheet = [(1.0 + 0.01 * k, SheetState(header=Header(stamp=1.0 + 0.01 * k), origin=np.zeros(3),
                                         normal=np.array([1.0, 0, 0]), axis_u=np.array([0, 1.0, 0]),
                                         corners=np.zeros((4, 3)), pushed_point=np.zeros(3), depth=0.0,
                                         stretch=0.05 + (0.03 if k == 10 else 0.0),
                                         membrane=np.zeros((2, 2))))
             for k in range(20)]
    target = [(1.0,
               SheetTarget(header=Header(stamp=0.99), contact_point=np.zeros(3), normal=np.array([1.0, 0, 0]),
                           axis_u=np.array([0, 1.0, 0]), axis_v=np.array([0, 0, 1.0]),
                           sheet_origin=np.zeros(3),
                           stretch=0.05, tension=100.0, stiffness=50.0, object_stiffness=50.0,
                           touching=True,
                           status="ok", source_stamp=0.99))]
    d = {"/arm/left/joint_state": [s for s in states if s[1].arm == "left"],
         "/arm/right/joint_state": [s for s in states if s[1].arm == "right"], "/world/sheet": sheet,
         "/sheet/target": target}
    s = sheet_summary(d)
    assert s["one_arm_holds"] == 3 and s["strain_true_max"] == pytest.approx(0.08)
    assert s["strain_over_plan_max"] == pytest.approx(0.03) and s["verdict"] == "MISSED"


# ---- the request at the surface contact, the object-depth gate, per press ----------------------------------

# front face x = 0, top face z = 30 mm, 8 mm edge about x = -8, z = 22 mm
BOX = "launch/scenes/rounded_box.yaml"
EDGE_C = np.array([-0.008, 0.0, 0.022])


def _sheet_state(t: float, origin, normal) -> SheetState:
    n = np.asarray(normal, float)
    return SheetState(header=Header(stamp=t), origin=np.asarray(origin, float), normal=n / np.linalg.norm(n),
                      axis_u=np.array([0.0, 1.0, 0.0]), corners=np.zeros((4, 3)), pushed_point=np.zeros(3),
                      depth=0.0, stretch=0.05, membrane=np.zeros((2, 2)))


def _edge_table():
    """The box's stroke from the front face over the edge onto the top: c = 1000 on the front face, 1500 on
    the edge's arc, 2500 on the top face (F = c·d^1.5, depths 0–20 mm in 0.5 mm steps)."""
    from messages import ObjectForceDepth

    front = [np.array([0.0, 0.0, z]) for z in (0.0, 0.01)]
    arc = [EDGE_C + 0.008 * np.array([np.cos(a), 0.0, np.sin(a)]) for a in np.radians(np.arange(0, 91, 15))]
    # above the bottom
    top = [np.array([x, 0.0, 0.03]) for x in (-0.008 - 0.002 * np.cos(np.radians(30)), -0.04)]
    nrm = ([np.array([1.0, 0, 0])] * 2
           + [np.array([np.cos(a), 0.0, np.sin(a)]) for a in np.radians(np.arange(0, 91, 15))]
           + [np.array([0, 0, 1.0])] * 2)
    c = np.array([1000.0] * 2 + [1500.0] * 7 + [2500.0] * 2)
    depths = np.linspace(0.0, 0.02, 41)
    return ObjectForceDepth(header=Header(stamp=0.5), points=np.array(front + arc + top),
                            normals=np.array(nrm),
                            names=["reference"] + [f"p{i}" for i in range(10)], depths=depths,
                            force=c[:, None] * depths[None, :] ** 1.5, scene_key="box")


def test_over_the_rounded_edge_the_request_is_looked_up_at_the_surface_not_at_the_dents_bottom():
    """A finger 10 mm into the sheet over the edge at 30°: the dent's bottom (2 mm past the edge's centre)
    projects onto the top face (2500), the surface contact onto the arc (1500); the sheet presents the arc's
    force."""
    from flexsheet.analysis.report_softness import force_depth_table, surface_points
    from flexsheet.model.scenes import load_scene

    u = np.array([np.cos(np.radians(30)), 0.0, np.sin(np.radians(30))])
    depth = 0.01
    bottom = EDGE_C + (0.008 - depth) * u
    msg = _edge_table()
    table = force_depth_table({"/object/force_depth": [(0.5, msg)]})
    assert table.force_at(bottom, depth) == pytest.approx(2500.0 * depth ** 1.5, rel=1e-9)  # the old look-up
    contacts = [(1.0 + 0.01 * k, ContactTruth(header=Header(stamp=1.0 + 0.01 * k), touching=True, depth=depth,
                                              force=1500.0 * depth ** 1.5, point=bottom, stiffness=1.0))
                for k in range(5)]
    sheets = [(t, _sheet_state(m.header.stamp, EDGE_C + 0.008 * u, u)) for t, m in contacts]
    d = {"/world/contact": contacts, "/world/sheet": sheets, "/object/force_depth": [(0.5, msg)]}
    q = surface_points(d, [m for _, m in contacts])
    assert np.allclose(q, EDGE_C + 0.008 * u, atol=1e-12)
    for scene in (None, load_scene(BOX)):
        r = felt_force(d, scales=[(0.0, 1.0)], scene=scene)
        assert r["n"] == 5 and r["requested_n"] == pytest.approx(1500.0 * depth ** 1.5, rel=1e-6)
        assert r["ratio"]["median"] == pytest.approx(1.0, abs=1e-6) and r["within_15pct"] == 1.0


def test_a_finger_1_mm_into_the_object_is_not_judged_for_softness_even_when_2_5_mm_into_the_sheet():
    """Front face (x = 0): a finger 1 mm in with the sheet 1.5 mm ahead (2.5 mm sheet depth, felt twice the
    request) and one 3 mm in with the sheet at the surface (felt as asked). The object's depth judges the
    second only; the sheet's depth (no scene) both."""
    from flexsheet.model.scenes import load_scene

    def c(t, x, depth, k):
        return (t,
                ContactTruth(header=Header(stamp=t), touching=True, depth=depth,
                             force=k * 1000.0 * depth ** 1.5,
                             point=np.array([x, 0.0, 0.01]), stiffness=1.0))

    contacts = [c(1.0, -0.001, 0.0025, 2.0), c(1.01, -0.003, 0.003, 1.0)]
    sheets = [(1.0, _sheet_state(1.0, [0.0015, 0, 0.01], [1, 0, 0])),
              (1.01, _sheet_state(1.01, [0, 0, 0.01], [1, 0, 0]))]
    d = {"/world/contact": contacts, "/world/sheet": sheets, "/object/force_depth": [(0.5, _table_msg())]}
    judged = felt_force(d, scales=[(0.0, 1.0)], scene=load_scene(BOX))
    assert judged["gate"] == "object_depth" and judged["n"] == 1 and judged["within_15pct"] == 1.0
    assert judged["felt_n"] == pytest.approx(1000.0 * 0.003 ** 1.5)
    both = felt_force(d, scales=[(0.0, 1.0)])
    assert both["gate"] == "sheet_depth" and both["n"] == 2 and both["within_15pct"] == 0.5


def test_each_press_gets_its_own_median_ratio():
    """Three presses (touches apart): 10 samples at ratio 1.0, 10 at 1.3, 10 at 0.95 (one of them 2.0): per
    press 1.0, 1.3, 0.95 → 2 of 3 within 15 %, median 1.0, worst 1.3; per sample 20 of 30 within."""
    contacts, t = [], 1.0
    for ratio in (1.0, 1.3, 0.95):
        for k in range(10):
            r = 2.0 if (ratio == 0.95 and k == 0) else ratio
            contacts.append((t, _contact(t, 0.01, 0.005, r * 1000.0 * 0.005 ** 1.5)))
            t += 0.01
        contacts.append((t, ContactTruth(header=Header(stamp=t), touching=False, depth=0.0, force=0.0,
                                         point=np.zeros(3), stiffness=0.0)))
        t += 0.5
    d = {"/world/contact": contacts, "/object/force_depth": [(0.5, _table_msg())]}
    r = felt_force(d, scales=[(0.0, 1.0)])
    pp = r["per_press"]
    assert pp["n"] == 3 and pp["ratios"] == pytest.approx([1.0, 1.3, 0.95], abs=1e-6)
    assert pp["within_15pct"] == pytest.approx(2 / 3) and pp["ratio_median"] == pytest.approx(1.0, abs=1e-6)
    assert pp["worst"] == pytest.approx(1.3, abs=1e-6)
    assert r["within_15pct"] == pytest.approx(19 / 30)


def test_the_inclusion_is_found_from_the_surface_contact_at_every_depth():
    """As the inclusion test, but each contact at the dent's bottom (depth behind the surface along −x, the
    sheet's normal +x): at 9 mm the bottom is farther than the 7 mm radius from the point above the inclusion,
    the surface contact is not, so all three depth bins count and the contrast is the 30 % felt."""
    from flexsheet.analysis.report_softness import inclusion_contrast

    class _Scene:
        inclusions = [type("I", (), {"center": (-0.007, 0.0, 0.02), "radius": 0.007})()]

    contacts, sheets = [], []
    for k in range(300):
        t = 1.0 + 0.02 * k
        z = 0.04 * (k % 100) / 99
        depth = 0.003 + 0.006 * ((k // 100) % 3) / 2
        felt = (1300.0 if abs(z - 0.02) <= 0.007 else 1000.0) * depth ** 1.5
        contacts.append((t, ContactTruth(header=Header(stamp=t), touching=True, depth=depth, force=felt,
                                         point=np.array([-depth, 0.0, z]), stiffness=1.0)))
        sheets.append((t, _sheet_state(t, [0.0, 0.0, 0.02], [1, 0, 0])))
    d = {"/world/contact": contacts, "/world/sheet": sheets,
         "/object/force_depth": [(0.5, _table_msg(1000.0, 1250.0))]}
    ic = inclusion_contrast(d, _Scene())
    assert len(ic["bins"]) == 3 and ic["felt"] == pytest.approx(0.30,
                                                                abs=1e-6) and ic["contrast_gain"] == [1.0]


def test_the_judged_samples_contacts_on_the_sheet_are_read_from_the_plan_at_their_time():
    """judged_contacts: (u, v) on the sheet of each judged sample, from the newest /sheet/target before it; a
    sample too shallow to judge is left out."""
    from flexsheet.analysis.report_softness import judged_contacts
    from messages import SheetTarget

    rng = np.random.default_rng(4)
    origin = rng.uniform(-0.02, 0.02, 3)
    u_ax, v_ax = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    offsets = rng.uniform(-0.06, 0.06, (4, 2))
    targets = [(1.0 + 0.1 * k, SheetTarget(header=Header(stamp=1.0 + 0.1 * k),
                                           contact_point=origin + su * u_ax + sv * v_ax,
                                           normal=np.array([1.0, 0, 0]),
                                           axis_u=u_ax, axis_v=v_ax, sheet_origin=origin, stretch=0.03,
                                           tension=50.0,
                                           stiffness=40.0, object_stiffness=40.0, touching=True, status="ok",
                                           source_stamp=1.0 + 0.1 * k)) for k, (su, sv) in enumerate(offsets)]
    depths = [0.004, 0.001, 0.006, 0.005]                     # the second is too shallow to judge
    contacts = [(1.05 + 0.1 * k, _sheet(1.05 + 0.1 * k, dp, 30.0 * dp)) for k, dp in enumerate(depths)]
    uv = judged_contacts({"/world/contact": contacts, "/sheet/target": targets})
    np.testing.assert_allclose(uv, offsets[[0, 2, 3]], atol=1e-12)
    assert judged_contacts({"/world/contact": contacts}).shape == (0, 2)
