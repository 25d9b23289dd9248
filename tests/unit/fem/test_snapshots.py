"""The cylinder's snapshot look-up (flexsheet/fem/snapshots.py): an analytic rotation-covariant table is
reproduced exactly, outside and bad input are refused, and the shipped node table stiffens from Hertz's force.
``_analytic_table`` and its cylinder (``R``, ``L``, ``C``) serve other modules' tests too."""

import math

import numpy as np
import pytest

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.snapshots import TABLE_VERSION, SnapshotGrid, SnapshotModel

# ---- snapshot look-up: an analytic rotation-covariant table must be reproduced exactly ---------------------
R, L, C = 0.035, 0.12, np.array([-0.035, 0.0, 0.0])


def _analytic_table(angles_deg, depths):
    """A table whose field, for a push at φ, is the rigid rotation by φ of f(θ − φ, y) (exactly what the
    cylinder's symmetry gives without the support), f linear in θ and y on the grid so bilinear look-up is
    exact."""
    g = SnapshotGrid(tuple(angles_deg), depths[-1], depths[1] - depths[0], 1.0, 0.001, 0.002)
    th, ys, rh = g.thetas(), g.ys(L / 2), g.rhos(R)
    a = np.radians(angles_deg)
    side = np.zeros((len(a), len(depths), len(th), len(ys), 3), np.float32)
    cap = np.zeros((len(a), len(depths), len(th), len(rh), 3), np.float32)
    for i, ai in enumerate(a):
        for j, d in enumerate(depths):
            rel = th - ai                                                # relative azimuth
            # radial component in the rotated frame
            fr = d * (1.0 + 0.3 * rel)[:, None] * (1.0 - ys / L)[None, :]
            ft = d * 0.2 * rel[:, None] * np.ones_like(ys)[None, :]        # tangential
            # display-frame components of (radial, tangential) at azimuth θ
            side[i, j, :, :, 0] = fr * np.cos(th)[:, None] - ft * np.sin(th)[:, None]
            side[i, j, :, :, 2] = fr * np.sin(th)[:, None] + ft * np.cos(th)[:, None]
            side[i, j, :, :, 1] = d * 0.1 * ys[None, :] / L * np.ones_like(rel)[:, None]
    return {"version": np.array(TABLE_VERSION), "E": np.array(1e4), "angles": a, "depths": np.asarray(depths),
            "theta": th, "y": ys, "rho": rh, "side": side, "cap": cap,
            "force": np.outer(np.ones(len(a)), 100.0 * np.asarray(depths)),
            "max_strain": np.zeros((len(a), len(depths))),
            "inverted": np.zeros((len(a), len(depths)), np.int64), "radius": np.array(R),
            "length": np.array(L),
            "center": C}


def test_snapshot_lookup_rotates_with_the_finger_and_mirrors():
    tab = _analytic_table([0.0, 10.0, 20.0], [0.0, 0.01, 0.02])
    th = np.radians(np.array([-40.0, -5.0, 3.0, 17.0, 33.0]))
    ys = np.array([0.0, 0.004, -0.012, 0.02, -0.03])
    verts = np.column_stack([C[0] + R * np.cos(th), ys, C[2] + R * np.sin(th)])
    sm = SnapshotModel(tab, verts, axial_max=0.005)
    for phi_deg, d in ((7.3, 0.013), (-14.0, 0.02), (20.0, 0.005)):
        phi = math.radians(phi_deg)
        u = sm.surface(phi, d)[0]
        s = abs(phi)
        tt = np.where(phi < 0, -th, th)
        rel = tt - s
        fr = d * (1.0 + 0.3 * rel) * (1.0 - np.abs(ys) / L)
        ft = d * 0.2 * rel
        ex = np.column_stack([fr * np.cos(tt) - ft * np.sin(tt), d * 0.1 * ys / L,
                              fr * np.sin(tt) + ft * np.cos(tt)])
        if phi < 0:
            ex[:, 2] *= -1.0
        assert np.abs(u - ex).max() < 1e-6 * d / 0.01, (phi_deg, np.abs(u - ex).max())
    F = sm.surface(math.radians(5.0), 0.015)[1:3]
    assert abs(F[0] - 1.5) < 1e-9 and abs(F[1] - 100.0) < 1e-9              # force and dF/dd from the table


def test_snapshot_lookup_rejects_outside_and_bad_input():
    tab = _analytic_table([0.0, 10.0], [0.0, 0.01])
    sm = SnapshotModel(tab, np.array([[0.0, 0.0, 0.0]]), axial_max=0.005)
    for args, word in (((math.radians(11.0), 0.005), "outside"), ((0.0, 0.011), "outside"),
                       ((0.0, -0.001), "outside"), ((float("nan"), 0.005), "finite")):
        with pytest.raises(ValueError, match=word):
            sm.surface(*args)
    with pytest.raises(ValueError, match="outside"):
        sm.surface(0.0, 0.005, 0.006)
    bad = dict(tab, version=np.array("old"))
    with pytest.raises(ValueError, match="version"):
        SnapshotModel(bad, np.zeros((1, 3)))


def test_shipped_node_table_is_the_default_scenes_and_stiffens_from_hertz():
    """The FEM node's snapshot table for the default scene (the paper's cylinder, Gent Jm 97.2) ships in
    flexsheet/fem/data under the key the node looks up (gmsh's version is in the key: a machine with another
    gmsh would fall back to the linear model). Its forces, checked against a closed form and not against the
    reference they came from: at a 2.5 mm push Hertz's sphere (8 mm) on the cylinder (R 35.4 mm), F = 4/3 E*
    √R_e d^1.5 with R_e = √(R′R″), R′ = (1/r + 1/R)⁻¹, R″ = r (Johnson, Contact Mechanics, §4.2), within 15 %
    at every azimuth (a finite body held on its back half is a little stiffer than a half-space); the force
    rises with every depth and stiffens (dF/dd over the last 2.5 mm step more than twice the first step's;
    Hertz's d^1.5 alone gives √13 ≈ 3.6 between those steps' midpoints)."""
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, table_key
    from flexsheet.model.scenes import SCENES_DIR, load_scene

    sc = load_scene(SCENES_DIR / "cylinder.yaml")
    mat = Material.of_scene(sc.material)
    assert mat.gent and mat.Jm == 97.2
    key = table_key(DEFAULT_GRID, DEFAULT_REF_SPEC, mat.nu, sc.finger.radius, sc.finger.contact, mat.Jm)
    tab = ArrayCache(None).load("snapshots", key)
    assert tab is not None, f"no shipped snapshot table under the node's key {key} in flexsheet/fem/data"
    assert np.allclose(np.degrees(tab["angles"]), DEFAULT_GRID.angles_deg)
    assert np.allclose(tab["depths"], DEFAULT_GRID.depths()) and tab["side"].dtype == np.float16
    r = sc.finger.radius
    R_e = math.sqrt(1.0 / (1.0 / r + 1.0 / R) * r)
    d = tab["depths"]
    hertz = 4.0 / 3.0 * mat.E_star * math.sqrt(R_e) * d[1] ** 1.5
    sm = SnapshotModel(tab, np.zeros((1, 3)), E=mat.E)
    for i, phi in enumerate(DEFAULT_GRID.angles_deg):
        f = sm.force[i]
        assert 1.0 <= f[1] / hertz < 1.15, (phi, f[1], hertz)
        assert f[0] == 0.0 and np.all(np.diff(f) > 0), (phi, f)
        k_first, k_last = (f[1] - f[0]) / (d[1] - d[0]), (f[-1] - f[-2]) / (d[-1] - d[-2])
        assert k_last > 2 * k_first, (phi, k_first, k_last)
