"""Shapes (flexsheet.model.shapes): closest point, centre ray, geodesic length, singular and edge
behaviour."""

import math

import numpy as np
import pytest
import trimesh

from flexsheet.model import geometry
from flexsheet.model.shape_base import Shape
from flexsheet.model.shapes import Cylinder, MeshShape, RoundedBox, make_shape, paper_cylinder
from flexsheet.model.vec import norm, sub

R = geometry.CYLINDER_RADIUS


def test_cylinder_centre_ray_is_radial_like_fig7():
    c = paper_cylinder()
    for ang in np.radians([0, 20, 45, 60, 120]):
        p = (-R + 0.05 * math.cos(ang), 0.01, 0.05 * math.sin(ang))
        pr = c.project(p)
        assert not pr.singular
        expect = (-R + R * math.cos(ang), 0.01, R * math.sin(ang))
        assert norm(sub(pr.point, expect)) < 1e-12
        assert abs(pr.distance - (0.05 - R)) < 1e-12
        assert abs(pr.normal[0] - math.cos(ang)) < 1e-12 and abs(pr.normal[2] - math.sin(ang)) < 1e-12


def test_cylinder_touches_sheet_at_origin():
    pr = paper_cylinder().project((0.03, 0.0, 0.0))
    assert norm(pr.point) < 1e-12 and pr.normal == (1.0, 0.0, 0.0)


def test_cylinder_arc_length_matches_R_times_angle():
    c = paper_cylinder()
    q0, q1 = c.point_at(0.0), c.point_at(math.radians(60))
    assert abs(c.arc_length(q0, q1) - R * math.pi / 3) < 1e-12
    # along the axis plus around: unrolled Pythagoras
    q2 = c.point_at(math.radians(30), h=0.02)
    assert abs(c.arc_length(q0, q2) - math.hypot(R * math.pi / 6, 0.02)) < 1e-9


def test_axis_singularity_uses_hint():
    c = paper_cylinder()
    pr = c.project((-R, 0.01, 0.0), hint=(0.0, 0.0, 1.0))
    assert pr.singular
    assert norm(sub(pr.point, (-R, 0.01, R))) < 1e-12 and pr.normal == (0.0, 0.0, 1.0)
    assert pr.distance == pytest.approx(-R)


def test_past_end_cap_is_continuous():
    c = paper_cylinder()
    pts = [(0.01, y, 0.0) for y in np.linspace(0.04, 0.09, 201)]
    prs = [c.project(p) for p in pts]
    jumps = [norm(sub(a.point, b.point)) for a, b in zip(prs, prs[1:], strict=False)]
    step = 0.05 / 200
    assert max(jumps) < 5 * step           # no jump of the contact across the rim
    assert prs[0].normal == (1.0, 0.0, 0.0)  # on the side: radial
    assert prs[-1].normal[1] > 0.99           # far past the cap: the cap normal (+y)
    assert all(not p.singular for p in prs)


def test_closest_point_signed_distance_cylinder_and_box():
    c = paper_cylinder()
    q, n, d = c.closest((-R, 0.0, 0.01))
    assert d == pytest.approx(-(R - 0.01))
    q, n, d = c.closest((0.01, 0.07, 0.0))                 # outside the rim
    assert d == pytest.approx(math.hypot(0.01, 0.01))
    b = RoundedBox((0, 0, 0), (0.03, 0.02, 0.01), radius=0.005)
    q, n, d = b.closest((0.0, 0.0, 0.05))
    assert d == pytest.approx(0.04) and n == pytest.approx((0, 0, 1))
    q, n, d = b.closest((0.04, 0.03, 0.0))                  # edge region: rounded corner
    assert d == pytest.approx(math.hypot(0.015, 0.015) - 0.005)


def test_rounded_box_edge_normals_continuous_sharp_box_jumps():
    rb = make_shape("box", {"center": (-0.03, 0, 0), "half_extents": (0.03, 0.03, 0.03), "radius": 0.005})
    sb = make_shape("box", {"center": (-0.03, 0, 0), "half_extents": (0.03, 0.03, 0.03), "radius": 0.0})
    ys = np.linspace(0.0, 0.06, 301)
    for shape, cont in ((rb, True), (sb, False)):
        ns = [shape.project((0.02, y, 0.0)).normal for y in ys]
        dn = max(norm(sub(a, b)) for a, b in zip(ns, ns[1:], strict=False))
        assert (dn < 0.2) == cont, (shape.r, dn)


def test_ray_exit_analytic_box_matches_generic_newton():
    b = make_shape("box", {"radius": 0.004, "rpy": (0.1, 0.2, 0.3)})
    rng = np.random.default_rng(0)
    for p in rng.uniform(-0.1, 0.1, (200, 3)):
        s = b.skeleton_point(tuple(p))
        w = np.asarray(p) - s
        if np.linalg.norm(w) < 1e-6:
            continue
        w = tuple(w / np.linalg.norm(w))
        q1, n1 = b._ray_exit(s, w)
        q2, n2 = Shape._ray_exit(b, s, w)
        assert norm(sub(q1, q2)) < 1e-7 and abs(b.signed_distance(q1)) < 1e-9


def test_sphere_geodesic_exact():
    s = make_shape("sphere", {"center": (0, 0, 0), "radius": 0.05})
    q0, q1 = (0.05, 0.0, 0.0), (0.0, 0.05, 0.0)
    assert s.arc_length(q0, q1) == pytest.approx(0.05 * math.pi / 2, rel=1e-12)


def test_mesh_convex_and_nonconvex():
    m = MeshShape(trimesh.creation.icosphere(3, radius=0.03))
    assert m.convex
    pr = m.project((0.1, 0.0, 0.0))
    assert pr.point[0] == pytest.approx(0.03, abs=1e-3) and pr.distance > 0.06
    assert m.signed_distance((0.0, 0.0, 0.01)) < 0
    # non-convex: union of two boxes (an L) -> closest point rule
    a = trimesh.creation.box((0.06, 0.02, 0.02))
    b = trimesh.creation.box((0.02, 0.06, 0.02))
    b.apply_translation((0.02, 0.02, 0))
    L = trimesh.boolean.union([a, b], engine="manifold") if trimesh.boolean.engines_available else None
    if L is not None and L.is_watertight:
        ms = MeshShape(L)
        assert not ms.convex
        pr = ms.project((0.0, 0.03, 0.0))
        q, n, d = ms.closest((0.0, 0.03, 0.0))
        assert pr.point == q


def test_bad_specs_raise_value_error_naming_field():
    with pytest.raises(ValueError, match="radius"):
        Cylinder((0, 0, 0), (0, 1, 0), -1.0, 0.1)
    with pytest.raises(ValueError, match="axis"):
        Cylinder((0, 0, 0), (0, 0, 0), 0.1, 0.1)
    with pytest.raises(ValueError, match="shape must be"):
        make_shape("torus")
    with pytest.raises(ValueError, match="watertight"):
        MeshShape(trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]]))
