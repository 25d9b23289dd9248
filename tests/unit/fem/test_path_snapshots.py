"""A scene's nonlinear path table (flexsheet/fem/path_snapshots.py): the served push is the linear model's solve of
that push plus the table's correction, bilinear along the stroke and in depth, with the force and stiffness
scaled by the table's ratios; outside the table (off the stroke, deeper) the linear model; bad tables are refused
naming the field; the shipped tables fit a fresh mesh; each station's correction moves with the contact (a bump
that travels along the stroke is served where the finger is, not as two half bumps at the stations). The model
(fixture ``model``) is tests/unit/conftest.py's."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.path_snapshots import (
    PathSnapshotModel,
    check_path_table,
    path_table_key,
    stiffness_from_force,
)
from flexsheet.fem.scene_model import SceneModel, finger_on_scene
from flexsheet.model.scenes import SCENES_DIR, load_scene

FRACTIONS = np.array([0.0, 0.5, 1.0])


DEPTHS = np.array([0.0, 0.002, 0.004, 0.006])


def _field(m: SceneModel, i: int, j: int) -> np.ndarray:
    """A closed-form correction at station i, depth j: a smooth field over the rendered vertices (m)."""
    v = m.rest_vertices.astype(float)
    return (1e-3 * (1 + i) * DEPTHS[j] / DEPTHS[-1]) * np.stack([np.cos(40 * v[:, 1]), np.sin(30 * v[:, 2]),
                                                                 np.ones(len(v))], axis=1)


def _table(m: SceneModel) -> dict:
    K, D = len(FRACTIONS), len(DEPTHS)
    corr = np.stack([np.stack([_field(m, i, j) for j in range(D)]) for i in range(K)]).astype(np.float32)
    fi, dj = np.meshgrid(np.arange(K), np.arange(D), indexing="ij")
    pts, nrm = m.scene.stroke_at(FRACTIONS)
    return {"fractions": FRACTIONS, "depths": DEPTHS, "points": pts, "normals": nrm,
            "rest_vertices": m.rest_vertices.astype(float), "correction": corr,
            "force_ratio": 1.0 + 0.1 * fi + 0.05 * dj, "stiffness_ratio": 2.0 + 0.1 * fi + 0.05 * dj,
            "inverted": np.zeros((K, D)), "max_strain": 0.01 * dj + 0.001 * fi, "reach": np.array(0.003)}


def _moved(m: SceneModel, field: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``field`` (S, 3) over the rendered vertices taken at the rest-surface point nearest v − ``delta`` for
    every vertex v (the module doc's move, here with the exact shift rather than the model's sub-fractions)."""
    import trimesh

    v = m.rest_vertices.astype(float)
    mesh = trimesh.Trimesh(v, m.faces, process=False)
    cp, _, tri = trimesh.proximity.closest_point(mesh, v - delta)
    bc = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], cp)
    return np.einsum("sk,skc->sc", bc, field[m.faces[tri]])


def test_served_push_is_the_linear_solve_plus_the_moved_correction(model):
    m = model
    m.path_table = None
    q, n = m.scene.stroke_at([0.75])                     # between stations 0.5 and 1.0, between depths 2 and 4 mm
    fg = finger_on_scene(q[0], n[0], 0.003, m.finger_radius)
    lin = m.update_finger(fg)
    assert lin.method == "condensed"
    m.attach_path_table(_table(m))
    try:
        up = m.update_finger(fg)
        assert up.valid and up.method == "path_snapshots" and up.status == "ok"
        f, lateral = m.path_table.locate(q[0])
        assert abs(f - 0.75) < 0.01 and lateral < 2e-4
        a, b = (f - 0.5) / 0.5, 0.5
        p = m.scene.stroke_at([f, 0.5, 1.0])[0]
        p_f, p_st = p[:1], p[1:]
        c1 = (1 - b) * _field(m, 1, 1) + b * _field(m, 1, 2)             # station 0.5 at 3 mm
        c2 = (1 - b) * _field(m, 2, 1) + b * _field(m, 2, 2)             # station 1.0 at 3 mm
        want = (1 - a) * _moved(m, c1, p_f[0] - p_st[0]) + a * _moved(m, c2, p_f[0] - p_st[1])
        held = m.mesh.fixed[m.surface_nodes]
        want[held] = 0.0
        got = (up.vertices.astype(float) - m.rest_vertices) - (lin.vertices.astype(float) - m.rest_vertices)
        # the model blends moves precomputed at sub-fractions <= 1 mm of path apart (here 0.62 mm) and a
        # float32 field; the exact move differs from it by the piecewise-linear field's change over part of a
        # sub-step: measured 2.0e-7 m of a 1.3e-3 m correction
        assert np.abs(got - want).max() < 1e-6, np.abs(got - want).max()
        unmoved = (1 - a) * c1 + a * c2
        unmoved[held] = 0.0
        # it did move: the fixed-vertex blend differs by 8.4e-6 m (a 0.6 mm move of this slow field), 40 x the
        # served field's distance from the exact move
        assert np.abs(got - unmoved).max() > 4e-6, np.abs(got - unmoved).max()
        assert np.abs(want).max() > 5e-4                                 # the correction is not nothing
        ratio = 1.0 + 0.1 * (1 + a) + 0.05 * 1.5
        assert up.force == pytest.approx(lin.force * ratio, rel=1e-6)
        assert up.stiffness == pytest.approx(lin.stiffness * (ratio + 1.0), rel=1e-6)
        assert up.max_strain == pytest.approx(0.01 * 1.5 + 0.001 * (1 + a), rel=1e-6)
        # at a station and a table depth the correction is that sample's, exactly
        q1, n1 = m.scene.stroke_at([0.5])
        at = m.update_finger(finger_on_scene(q1[0], n1[0], 0.004, m.finger_radius))
        m.path_table, keep = None, m.path_table
        base = m.update_finger(finger_on_scene(q1[0], n1[0], 0.004, m.finger_radius))
        m.path_table = keep
        w = _field(m, 1, 2)
        w[held] = 0.0
        assert np.abs((at.vertices.astype(float) - base.vertices) - w).max() < 2e-7
    finally:
        m.path_table = None


def test_outside_the_table_the_linear_model_serves(model):
    m = model
    m.attach_path_table(_table(m))
    try:
        q, n = m.scene.stroke_at([0.5])
        side = np.cross(n[0], [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        off = q[0] + 0.006 * side                                        # 6 mm off the stroke, reach 3 mm
        p_off, n_off = m.surface.project(off)[:2]
        assert m.path_table.locate(p_off)[1] > 0.003
        assert m.update_finger(finger_on_scene(p_off, n_off, 0.003, m.finger_radius)).method == "condensed"
        deep = m.update_finger(finger_on_scene(q[0], n[0], 0.008, m.finger_radius))    # table to 6 mm
        assert deep.method == "condensed"
        assert m.update_finger(finger_on_scene(q[0], n[0], 0.006, m.finger_radius)).method == "path_snapshots"
        assert m.update_finger(finger_on_scene(q[0], n[0], 0.0, m.finger_radius)).depth == 0.0
    finally:
        m.path_table = None


def test_bad_tables_are_refused_naming_the_field(model):
    m = model
    good = _table(m)
    check_path_table(good)
    for field, bad, msg in (("correction", None, "field 'correction' missing"),
                            ("fractions", np.array([0.0, 0.7, 0.5]), "fractions must be"),
                            ("depths", np.array([0.001, 0.002, 0.004, 0.006]), "depths must ascend from 0"),
                            ("force_ratio", np.ones((2, 4)), r"force_ratio has shape \(2, 4\)"),
                            ("reach", np.array(0.5), "reach must be"),
                            ("max_strain", np.full((3, 4), np.nan), "max_strain holds non-finite")):
        t = dict(good)
        if bad is None:
            del t[field]
        else:
            t[field] = bad
        with pytest.raises(ValueError, match=msg):
            m.attach_path_table(t)
    moved = dict(good, rest_vertices=good["rest_vertices"] + 1e-5)
    with pytest.raises(ValueError, match="another real-time mesh"):
        m.attach_path_table(moved)
    path, _ = m.scene.stroke_at(np.linspace(0, 1, 50))
    pm = PathSnapshotModel(good, m.rest_vertices, m.faces, path, np.linspace(0, 1, 50))
    with pytest.raises(ValueError, match="finite"):
        pm.lookup(float("nan"), 0.002)
    assert m.path_table is None


def test_stiffness_from_force_is_second_order_on_a_power_law():
    d = np.linspace(0.0, 0.05, 21)
    f = 3.0 * d ** 1.5 + 40.0 * d ** 2
    k = stiffness_from_force(f, d)
    exact = 4.5 * d ** 0.5 + 80.0 * d
    assert np.abs(k[2:-1] - exact[2:-1]).max() < 0.01 * exact[-1]
    assert abs(k[-1] - exact[-1]) < 0.02 * exact[-1]
    with pytest.raises(ValueError, match="ascending"):
        stiffness_from_force(f[:3], d[[0, 2, 1]])


@pytest.mark.parametrize("name, stations", [("rounded_box", 13), ("organ", 7)])
def test_the_shipped_path_tables_are_found_under_their_keys_and_fit_a_fresh_mesh(name, stations):
    """The FEM node on rounded_box.yaml and organ.yaml finds the shipped path table
    (flexsheet/fem/data) under its key, and the table's rendered vertices are exactly the boundary corner nodes of the
    scene's mesh meshed anew here (gmsh is deterministic for one version: a table on another mesh would be
    refused at attach time)."""
    from flexsheet.fem.scene_mesh import DEFAULT_SCENE_SPEC, scene_mesh
    from flexsheet.fem.scene_model import scene_cache_key

    sc = load_scene(SCENES_DIR / f"{name}.yaml")
    r = sc.finger.radius
    key = path_table_key(sc.key(), scene_cache_key(sc, DEFAULT_SCENE_SPEC, 2, r, r + 0.004))
    t = ArrayCache(None).load("pathsnap", key)
    assert t is not None, f"no shipped pathsnap_{key}.npz"
    check_path_table(t)
    assert len(t["fractions"]) == stations and t["depths"][-1] == pytest.approx(0.05)
    m = scene_mesh(sc, DEFAULT_SCENE_SPEC).mesh
    corners = m.points[np.unique(np.asarray(m.faces)[:, :3])]
    rv = np.asarray(t["rest_vertices"])
    assert rv.shape == corners.shape
    assert np.abs(np.sort(rv, axis=0) - np.sort(corners, axis=0)).max() < 1e-8      # float32 rest vertices
    # the correction is what the table is for: centimetres deep in, nothing at the surface's rest
    c = np.linalg.norm(np.asarray(t["correction"]), axis=-1).max(axis=-1)        # (K, D)
    assert np.all(c[:, 0] == 0) and c[:, -1].min() > 0.005


def _flat_bump_table():
    """A flat 1 mm grid (z = 0, x −10..30 mm, y −10..10 mm), a straight 20 mm stroke along +x, stations at x =
    0, 10, 20 mm, and at the table's 10 mm depth each station's correction a Gaussian bump (A 5 mm along −z,
    σ 4 mm) centred on its own contact: what a push's correction looks like, travelling with the finger."""
    xs, ys = np.arange(-0.010, 0.0305, 0.001), np.arange(-0.010, 0.0105, 0.001)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    nx, ny = len(xs), len(ys)
    k = (np.arange(nx - 1)[:, None] * ny + np.arange(ny - 1)[None, :]).ravel()
    faces = np.concatenate([np.stack([k, k + ny, k + ny + 1], 1), np.stack([k, k + ny + 1, k + 1], 1)])
    A, sig = 0.005, 0.004

    def bump(cx):
        out = np.zeros_like(v)
        out[:, 2] = -A * np.exp(-((v[:, 0] - cx) ** 2 + v[:, 1] ** 2) / sig ** 2)
        return out

    corr = np.zeros((3, 2, len(v), 3), np.float32)
    for s_ in range(3):
        corr[s_, 1] = bump(0.010 * s_)
    pts = np.array([[0.0, 0, 0], [0.010, 0, 0], [0.020, 0, 0]])
    table = {"fractions": np.array([0.0, 0.5, 1.0]), "depths": np.array([0.0, 0.01]), "points": pts,
             "normals": np.tile([0.0, 0.0, 1.0], (3, 1)), "rest_vertices": v, "correction": corr,
             "force_ratio": np.ones((3, 2)), "stiffness_ratio": np.ones((3, 2)), "inverted": np.zeros((3, 2)),
             "max_strain": np.zeros((3, 2)), "reach": np.array(0.004)}
    path = np.stack([np.linspace(0.0, 0.020, 201), np.zeros(201), np.zeros(201)], axis=1)
    return table, v, faces, path, np.linspace(0.0, 1.0, 201), bump, A


def test_a_station_correction_moves_with_the_contact_along_the_stroke():
    """Between stations the served correction is the bump where the finger is (within the 1 mm grid's linear
    interpolation: measured 0.1 % on a sub-fraction, 1.5 % between them), where a fixed-vertex blend
    gives two half bumps (79 % of the height off at the finger); at a station it is the station's, exactly; along
    the stroke it changes smoothly (no jump at the sub-fractions or the stations)."""
    table, v, faces, path, pf, bump, A = _flat_bump_table()
    pm = PathSnapshotModel(table, v, faces, path, pf)
    for f in (0.25, 0.275, 0.6, 0.83):                  # on a sub-fraction (x = 5 mm) and between them
        got = pm.lookup(f, 0.01)[0].astype(float)
        want = bump(0.020 * f)
        assert np.abs(got - want).max() < 0.03 * A, (f, np.abs(got - want).max() / A)
    i, a = (0, 0.5)                                       # f = 0.25: what a fixed-vertex blend serves there
    fixed = (1 - a) * table["correction"][i, 1] + a * table["correction"][i + 1, 1]
    assert np.abs(fixed - bump(0.005)).max() > 0.7 * A
    assert np.abs(pm.lookup(0.5, 0.01)[0] - table["correction"][1, 1]).max() < 1e-6 * A
    assert np.abs(pm.lookup(0.5, 0.005)[0] - 0.5 * table["correction"][1, 1]).max() < 1e-6 * A
    walk = np.stack([pm.lookup(f, 0.01)[0] for f in np.linspace(0.0, 1.0, 1001)]).astype(float)
    step = np.abs(np.diff(walk, axis=0)).max()
    assert step < 0.01 * A, step / A                      # a 0.02 mm move of the bump: ~0.004 A
    assert np.abs(walk[250] - walk[0]).max() > 0.5 * A    # and it does travel
    with pytest.raises(ValueError, match="faces must be"):
        PathSnapshotModel(table, v, faces + len(v), path, pf)
