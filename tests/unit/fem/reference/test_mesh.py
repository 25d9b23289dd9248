"""The reference's mesh (flexsheet/fem/reference/mesh.py): the tip and skin refinements, the cut half mesh and
the force it brings the half model to."""

import math
from dataclasses import replace

import numpy as np
import pytest

from flexsheet.fem.material import Material
from flexsheet.fem.reference import hyperelastic as H
from flexsheet.fem.reference import mesh as RM
from flexsheet.fem.reference import path_solver as PS


def test_tip_refinement_is_fine_at_the_push_point_only():
    """The tip option sizes the material at the push point itself (what ends up stretched over the fingertip);
    a spec without it keeps its key."""
    base = RM.RefSpec(0.016, 0.008, 0.012, half_z=True)
    tip = replace(base, tip_h=0.002, tip_radius=0.005)
    assert tip.key() == base.key() + ",tip=0.002/0.005"

    def edges(spec):
        m = RM.reference_mesh(spec, 0.0)
        e = np.concatenate([m.tets[:, [a, b]] for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        apex = m.center + np.array([m.radius, 0.0, 0.0])
        dist = np.linalg.norm(m.points[e].mean(axis=1) - apex, axis=1)
        return m, np.linalg.norm(m.points[e[:, 0]] - m.points[e[:, 1]], axis=1), dist

    m0, l0, d0 = edges(base)
    m1, l1, d1 = edges(tip)
    assert np.median(l1[d1 < 0.004]) < 0.5 * np.median(l0[d0 < 0.004]) and np.median(l1[d1 < 0.004]) < 0.003
    # far away: unchanged
    assert np.median(l1[d1 > 0.030]) == pytest.approx(np.median(l0[d0 > 0.030]), rel=0.15)
    assert len(m1.points) > len(m0.points)
    for kw, word in ((dict(tip_h=0.009), r"tip_h must be 0 \(no tip refinement\) or in \[0.0005, "
                                         r"h_fine=0.008\] m"),
                     (dict(tip_h=float("nan")), "tip_h must be"), (dict(tip_h=0.002, tip_radius=0.001),
                                                                    "tip_radius must be >= tip_h")):
        with pytest.raises(ValueError, match=word):
            replace(base, **kw)


def test_skin_refinement_is_fine_in_the_surface_layer_around_the_push_only():
    """The skin option sizes the surface layer near the push point; the rest of the mesh and the key of a
    spec without it are unchanged (cached references keep their keys)."""
    base = RM.RefSpec(0.016, 0.008, 0.012, half_z=True)
    skin = replace(base, skin_h=0.003, skin_radius=0.015, skin_depth=0.004)
    assert base.key() == "h=0.016,hf=0.008,rr=0.012,hz=1" and skin.key().endswith(",sk=0.003/0.015/0.004")

    def edges(spec):
        m = RM.reference_mesh(spec, 0.0)
        e = np.concatenate([m.tets[:, [a, b]] for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        mid = m.points[e].mean(axis=1) - m.center
        length = np.linalg.norm(m.points[e[:, 0]] - m.points[e[:, 1]], axis=1)
        r = np.hypot(mid[:, 0], mid[:, 2])
        # along the surface from the push
        lat = np.hypot(mid[:, 1], m.radius * np.arctan2(mid[:, 2], mid[:, 0]))
        in_skin = (r > m.radius - 0.002) & (lat < 0.010)
        far = lat > 0.040
        return m, length, in_skin, far

    m0, l0, s0, f0 = edges(base)
    m1, l1, s1, f1 = edges(skin)
    assert np.median(l1[s1]) < 0.6 * np.median(l0[s0]) and np.median(l1[s1]) < 0.0045
    assert np.median(l1[f1]) == pytest.approx(np.median(l0[f0]), rel=0.15)       # far away: unchanged
    assert len(m1.points) > len(m0.points)
    for kw, word in ((dict(skin_h=0.009), r"skin_h must be 0 \(no skin\) or in \[0.0005, h_fine=0.008\] m, "
                                          r"got 0.009"),
                     (dict(skin_h=float("nan")), "skin_h must be"), (dict(skin_h=-0.003), "skin_h must be"),
                     (dict(skin_h=0.003, skin_depth=0.0), "skin_depth must be > 0 m, got 0.0"),
                     (dict(skin_h=0.003, skin_radius=float("nan")), "skin_radius must be > 0 m, got nan")):
        with pytest.raises(ValueError, match=word):
            replace(base, **kw)
    with pytest.raises(ValueError, match=r"skin_depth must be >= skin_h = 0.003 m \(one element thick\), got "
                                         r"0.002"):
        replace(base, skin_h=0.003, skin_depth=0.002)
    with pytest.raises(ValueError, match="size balls"):
        RM.reference_mesh(replace(base, skin_h=0.0005, skin_depth=0.0005, skin_radius=0.05), 0.0)


def test_cut_half_mesh_has_nodes_on_the_plane_through_the_push_axis():
    """``cut``: the half model's mesh conforms to the plane through the cylinder's axis and the push axis at
    the push's azimuth (a line of nodes under the fingertip, as the quarter model has on its mirror plane);
    without it at most a stray node lies on that plane. A quarter model ignores it (same key, same mesh)."""
    base = RM.RefSpec(0.016, 0.008, 0.012)
    cut = replace(base, cut=True)
    assert cut.key() == base.key() + ",cut"
    assert replace(base, half_z=True, cut=True).key() == replace(base, half_z=True).key()
    for ang in (0.0, 20.0):
        a = math.radians(ang)
        normal = np.array([-math.sin(a), 0.0, math.cos(a)])
        push = np.array([math.cos(a), 0.0, math.sin(a)])
        for spec, want in ((base, False), (cut, True)):
            m = RM.reference_mesh(spec, ang)
            rel = m.points - m.center
            on = np.abs(rel @ normal) < 1e-9
            assert (on.sum() > 20) == want and (want or on.sum() <= 2), (ang, spec.key(), on.sum())
            # the plane's nodes reach the push point on the surface and lie on the push side and behind
            if want:
                assert np.min(np.linalg.norm(rel[on] - m.radius * push, axis=1)) < 1e-9
                assert (rel[on] @ push).min() < -0.9 * m.radius
                # conforming: the two volumes share their nodes, so no boundary face lies on the plane
                assert not np.all(on[m.faces], axis=1).any()
                assert len(np.unique(np.round(m.points, 12), axis=0)) == len(m.points)
    from flexsheet.fem.mesh import cylinder_part_mesh

    for kw in (dict(cut_deg=0.0, half_z=True), dict(cut_deg=float("nan"))):
        with pytest.raises(ValueError, match="cut_deg must be a finite azimuth"):
            cylinder_part_mesh(0.016, 0.008, 0.012, **kw)


def test_cut_brings_the_half_model_to_the_quarter_models_force():
    """Why the off-axis snapshots are solved on cut meshes: at azimuth 0 a half model meshed without nodes on
    the plane through the push axis is stiffer than the quarter model of the same sizes (on this coarse mesh
    +3.4 % at 10 mm; +8-9 % at 40-50 mm on the 3.4 mm one, the experiment's mirror study); cut, it is within a
    fifth of that gap. (Three solves, ~25 s.)"""
    base = RM.RefSpec(0.016, 0.012, 0.018, path_depth=0.055)
    f = {}
    for name, spec in (("quarter", replace(base, half_z=True)), ("half", base),
                       ("cut", replace(base, cut=True))):
        m = H.HyperelasticModel(RM.reference_mesh(spec, 0.0), Material(), sym_y=True, sym_z=spec.half_z)
        (st,) = PS.solve_path(m, 0.0, [0.01], 0.008, step=0.0025)
        assert st.converged
        f[name] = st.force
    gap_half, gap_cut = abs(f["half"] / f["quarter"] - 1), abs(f["cut"] / f["quarter"] - 1)
    assert gap_half > 0.02 and gap_cut < gap_half / 3, f
