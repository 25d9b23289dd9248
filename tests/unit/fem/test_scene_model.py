"""The FEM on any scene, in real time (flexsheet/fem/scene_model.py): the update equals the full solve and
names its scene, the organ's update equals a dense float64 solve of the same system with the same verdicts,
bad input gives clear errors, and the path table is found under the node's key."""

from __future__ import annotations

import numpy as np
import pytest
from test_path_snapshots import _table

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.path_snapshots import path_table_key
from flexsheet.fem.scene_mesh import scene_mesh
from flexsheet.fem.scene_model import (
    SceneModel,
    SurfaceIndex,
    attach_scene_table,
    finger_on_scene,
    scene_finger,
)
from flexsheet.fem.solver import FemModel, solve_full
from flexsheet.model.scenes import SCENES_DIR, load_scene
from unit.fem.conftest import small_push_scene


def test_scene_model_realtime_matches_the_full_solve_and_names_its_scene(tmp_path):
    sc = small_push_scene()
    m = SceneModel(sc, MeshSpec(0.015, 0.006, 0.012), order=1, cache_dir=str(tmp_path))
    assert m.scene_key == sc.key() and not m.cache_hit
    q, n = sc.stroke_points(2)
    tip = q[0] - 0.004 * n[0]
    u = m.update(tip)
    assert u.valid and u.method == "condensed" and abs(u.depth - 0.004) < 2e-4
    ref = solve_full(m.model, m.finger(tip))
    assert (abs(u.force - ref.force) < 1e-9 + 1e-6 * ref.force
            and abs(u.stiffness - ref.stiffness) < 1e-6 * ref.stiffness)
    us = u.vertices - m.rest_vertices
    assert np.allclose(us, ref.u[m.surface_nodes], atol=1e-7)
    # the vertex under the finger moved by about the depth, into the body
    j = int(np.argmin(np.linalg.norm(m.rest_vertices - q[0], axis=1)))
    assert abs(float(us[j] @ -n[0]) - 0.004) < 0.0015
    # a light touch reports the stiffness of a 0.5 mm press at the same point, its own force
    light = m.update_finger(finger_on_scene(q[0], n[0], 0.0002, m.finger_radius))
    press = m.update_finger(finger_on_scene(q[0], n[0], 0.0005, m.finger_radius))
    assert light.stiffness == press.stiffness > 0 and 0 < light.force < press.force
    m2 = SceneModel(sc, MeshSpec(0.015, 0.006, 0.012), order=1, cache_dir=str(tmp_path))
    assert m2.cache_hit and abs(m2.update(tip).force - u.force) < 1e-12


def test_bad_input_gives_clear_errors():
    sc = load_scene(SCENES_DIR / "sphere.yaml")
    with pytest.raises(ValueError, match="scene must be"):
        scene_mesh("launch/scenes/sphere.yaml")
    with pytest.raises(ValueError, match="finger_radius"):
        SceneModel(sc, finger_radius=0.5, cache_dir=None)
    with pytest.raises(ValueError, match="order"):
        SceneModel(sc, order=3, cache_dir=None)
    surf = SurfaceIndex(sc)
    with pytest.raises(ValueError, match="tip must be a finite"):
        scene_finger([np.nan, 0.0, 0.0], surf, 0.008, 0.05)
    with pytest.raises(ValueError, match="beyond max_depth"):
        scene_finger(sc.center, surf, 0.008, 0.02)
    with pytest.raises(ValueError, match="support"):                   # the held back of the sphere
        scene_finger(sc.center - np.array([sc.object.radius - 0.002, 0.0, 0.0]), surf, 0.008, 0.05,
                     sc.fixed_mask)
    fg = scene_finger(np.array([0.01, 0.0, 0.0]), surf, 0.008, 0.05)   # outside: no contact
    assert fg.depth == 0.0 and np.allclose(fg.direction, [-1.0, 0.0, 0.0], atol=0.02)
    with pytest.raises(ValueError, match="depth must be"):
        finger_on_scene([0, 0, 0], [1, 0, 0], -0.001, 0.008)
    sm = scene_mesh(sc, MeshSpec(0.02, 0.02, 0.0))
    mat = Material()
    with pytest.raises(ValueError, match="E_elem must have shape"):
        FemModel(sm.mesh, mat, E_elem=np.ones(3))
    with pytest.raises(ValueError, match="E_elem must be > 0"):
        FemModel(sm.mesh, mat, E_elem=-np.ones(len(sm.mesh.tets)))
    with pytest.raises(ValueError, match="nu_elem must be in"):
        FemModel(sm.mesh, mat, nu_elem=np.full(len(sm.mesh.tets), 0.5))
    with pytest.raises(ValueError, match="support holds no boundary point"):
        FemModel(sm.mesh, mat, support=lambda p: np.zeros(len(p), bool))
    # per-element material equal everywhere assembles the scalar-material stiffness
    a = FemModel(sm.mesh, mat, order=2)
    b = FemModel(sm.mesh, mat, order=2, E_elem=np.full(len(sm.mesh.tets), mat.E),
                 nu_elem=np.full(len(sm.mesh.tets), mat.nu))
    assert abs(a.K - b.K).max() <= 1e-12 * abs(a.K).max()


def _dense_condensed(z, fg):
    """Reference for one push: the condensed contact system of the cached float64 Green's functions solved
    straightforwardly (``numpy.linalg.solve`` on G_aa, u = G_oaᵀ f) — not the real-time code path."""
    from flexsheet.fem.contact import imposed_displacement

    assert not imposed_displacement(z["noncand_points"], fg)[0].any()
    inside, ubar = imposed_displacement(z["cand_points"], fg)
    k = np.flatnonzero(inside)
    a = (3 * k[:, None] + np.arange(3)[None, :]).ravel()
    G_cc, G_co = np.asarray(z["G_cc"], np.float64), np.asarray(z["G_co"], np.float64)
    f = np.linalg.solve(G_cc[np.ix_(a, a)], np.column_stack([ubar[k].ravel(), np.tile(fg.direction, len(k))]))
    u_out = (G_co[a].T @ f[:, 0]).reshape(-1, 3)
    force = max(float(f[:, 0].reshape(-1, 3).sum(axis=0) @ fg.direction), 0.0)
    stiff = max(float(f[:, 1].reshape(-1, 3).sum(axis=0) @ fg.direction), 0.0)
    return u_out, force, stiff


def test_organ_realtime_update_equals_a_dense_float64_solve_of_the_same_system():
    """The organ's real-time update (single-precision condensed solve, sparse strain/inversion operator, fold
    test as a sparse product; the 1 kHz work) against the same linear system solved plainly in float64:
    at the timed pushes (5 stroke points × 5/20/50 mm) and a light touch, the surface displacements agree
    within 0.1 µm (the display's pixel is 700 µm), force and dF/dd within 1e-6, and the checks the node
    relies on — inverted elements, max strain over the monitor tets near the contact, folded surface
    triangles (np.cross) — give the same verdicts. Three pushes also match the full sparse FEM solve."""
    from flexsheet.fem.deformation_checks import element_checks
    from flexsheet.fem.scene_model import STIFFNESS_FLOOR

    sc = load_scene(SCENES_DIR / "organ.yaml")
    rt = SceneModel(sc)                               # the default cache, as the experiment and the node
    z = rt.cache.load("scenecap", rt.cache_key)
    assert z is not None
    pts = rt.mesh.points
    pos = np.full(len(pts), -1, np.int64)
    pos[z["out_pts"]] = np.arange(len(z["out_pts"]))
    rows = pos[rt.surface_nodes]
    tets = rt.mesh.tets
    mon = np.all(pos[tets] >= 0, axis=1) & np.all(z["monitor"][tets], axis=1)
    tets = tets[mon]
    cen = pts[tets].mean(axis=1)
    rest = pts[rt.surface_nodes]
    n0 = np.cross(rest[rt.faces[:, 1]] - rest[rt.faces[:, 0]], rest[rt.faces[:, 2]] - rest[rt.faces[:, 0]])
    q, n = sc.stroke_points(5)
    worst, seen_invalid, seen_inverted = 0.0, 0, 0
    for i in range(5):
        for d in (0.0002, 0.005, 0.02, 0.05):
            fg = finger_on_scene(q[i], n[i], d, rt.finger_radius)
            u_out, force, stiff = _dense_condensed(z, fg)
            us_ref = np.where(rows[:, None] >= 0, u_out[rows], 0.0)
            us, F, K = rt.surface_displacement(fg)
            err = float(np.abs(us - us_ref).max())
            worst = max(worst, err)
            assert err < 1e-7, (i, d, err)
            assert (abs(F - force) <= 1e-6 * force and abs(K - stiff) <= 1e-6 * stiff), (i, d, F, force, K,
                                                                                         stiff)
            up = rt.update_finger(fg)
            if d < STIFFNESS_FLOOR:                    # a light touch reports the 0.5 mm press's dF/dd
                stiff = _dense_condensed(z, finger_on_scene(q[i], n[i], STIFFNESS_FLOOR, rt.finger_radius))[2]
            assert abs(up.stiffness - stiff) <= 1e-6 * stiff or not up.valid
            u_nodes = np.zeros((len(pts), 3))
            u_nodes[z["out_pts"]] = u_out
            r = rt.finger_radius + d + 2 * rt.spec.h_fine
            near = np.linalg.norm(cen - fg.contact_point, axis=1) <= r
            strain, inv = element_checks(pts, tets[near], u_nodes)
            x = rest + us_ref
            nn = np.cross(x[rt.faces[:, 1]] - x[rt.faces[:, 0]], x[rt.faces[:, 2]] - x[rt.faces[:, 0]])
            folded = int(np.count_nonzero(np.einsum("ij,ij->i", nn, n0) <= 0.0))
            assert (up.inverted == inv and abs(up.max_strain - strain) <= 1e-5 * strain), (i, d, up, strain,
                                                                                           inv)
            assert (up.valid == (folded == 0)
                    and (up.status == "ok") == (folded == 0 and inv == 0 and strain <= 1.0))
            if folded:
                assert up.status == f"linear_invalid:folded_surface={folded}"
            else:
                assert np.abs(up.vertices - (rest + us_ref)).max() < 1e-7
                assert abs(up.force - force) <= 1e-6 * force
            seen_invalid += not up.valid
            seen_inverted += inv > 0
    assert seen_invalid >= 3 and seen_inverted >= 5           # the deep pushes exercise the failure checks
    model = rt.model
    for d in (0.005, 0.02, 0.05):                             # the condensed system is the FEM's
        fg = finger_on_scene(q[2], n[2], d, rt.finger_radius)
        full = solve_full(model, fg)
        us, F, K = rt.surface_displacement(fg)
        assert np.abs(us - full.u[rt.surface_nodes]).max() < 1e-7
        assert abs(F - full.force) <= 1e-6 * full.force and abs(K - full.stiffness) <= 1e-6 * full.stiffness


def test_attach_scene_table_finds_the_path_table_under_the_node_key(model, tmp_path):
    m = model
    cache = ArrayCache(str(tmp_path))
    kind, where = attach_scene_table(m, cache)
    assert (kind, where) == ("path", None) and m.path_table is None
    cache.save("pathsnap", path_table_key(m.scene_key, m.cache_key), _table(m))
    try:
        kind, where = attach_scene_table(m, cache)
        assert (kind, where) == ("path", "cache") and m.path_table is not None
        assert len(m.path_table.fractions) == 3 and m.path_table.depth_max == pytest.approx(0.006)
    finally:
        m.path_table = None
