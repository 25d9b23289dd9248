"""The snapshot table's build (flexsheet/fem/reference/snapshot_build.py): the float16 packing, and a table
extended azimuth by azimuth from a shipped one."""

import math
import os
from dataclasses import replace

import numpy as np
import pytest
from test_snapshots import C, R, _analytic_table

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.reference import mesh as RM
from flexsheet.fem.reference import path_solver as PS
from flexsheet.fem.snapshots import SnapshotGrid, SnapshotModel

MAT = Material()


def test_packed_table_rounds_within_float16_and_looks_up_as_the_original(tmp_path):
    """pack_table: float16 surface fields, off by at most 2^-16 m (|u| < 64 mm), read back through the shipped
    directory (compressed) into a SnapshotModel that answers within that of the float32 table; a value no
    displacement has is refused."""
    from flexsheet.fem.reference.snapshot_build import pack_table

    tab = _analytic_table([0.0, 10.0], [0.0, 0.015, 0.03])            # |u| up to 44 mm
    assert 0.032 < np.abs(tab["side"]).max() < 0.064
    packed, err = pack_table(tab)
    assert packed["side"].dtype == np.float16 and packed["force"] is tab["force"]
    assert 0.0 < err <= 2.0 ** -16 and err == np.abs(packed["side"].astype(np.float32) - tab["side"]).max()
    c = ArrayCache(None, shipped_dir=str(tmp_path / "data"))
    path = c.ship("snapshots", "k" * 24, packed)
    assert (path.startswith(str(tmp_path / "data"))
            and c.load("snapshots", "k" * 24)["side"].dtype == np.float16)
    mtime = os.stat(path).st_mtime_ns
    assert c.ship("snapshots", "k" * 24, packed) == path and os.stat(path).st_mtime_ns == mtime   # same: kept
    th = np.radians(np.array([-20.0, 0.0, 15.0]))
    verts = np.column_stack([C[0] + R * np.cos(th), [0.0, 0.01, -0.02], C[2] + R * np.sin(th)])
    a = SnapshotModel(tab, verts).surface(math.radians(6.0), 0.02)[0]
    b = SnapshotModel(c.load("snapshots", "k" * 24), verts).surface(math.radians(6.0), 0.02)[0]
    assert np.abs(a - b).max() <= 2.0 ** -16 and np.abs(a).max() > 0.01
    with pytest.raises(ValueError, match="float16"):
        pack_table(dict(tab, cap=np.full_like(tab["cap"], 1e6)))
    with pytest.raises(ValueError, match="shipped directory"):
        ArrayCache(str(tmp_path), shipped_dir=None).ship("snapshots", "k" * 24, packed)


def _linear_states(model, ang, depths, log=None):
    """PathStates whose displacement is a linear field of the rest position scaled by depth and azimuth: P2
    holds it exactly, so the table samples it exactly wherever it is sampled (u = 20·d·(1 + φ)·A·(x − c), A
    fixed)."""
    A = np.array([[0.3, 0.0, 0.1], [0.0, -0.2, 0.0], [0.1, 0.0, 0.4]])
    X = model.points - model.mesh.center
    out = []
    for d in depths:
        u = 20.0 * d * (1.0 + math.radians(ang)) * X @ A.T
        out.append(PS.PathState(depth=float(d), u=u, force=100.0 * d * (1.0 + ang), force_vec=np.zeros(3),
                               iterations=3, converged=True, min_detF=1.0, inverted=0, max_strain=0.01 * d,
                               penetration=0.0, n_contact=0))
    if log is not None:
        log.append(ang)
    return out


def test_a_table_is_extended_azimuth_by_azimuth_from_a_shipped_one(tmp_path):
    """build_table(reuse=...): a table on fewer azimuths (here packed to float16 and found through the cache
    as a shipped one would be) gives its azimuths as they are stored, and only the new azimuth is solved; the
    extended table equals the one built whole within float16's rounding (exactly at the solved azimuth); a
    table sampled otherwise is refused, and reusable_table finds only a proper subset of the grid's
    azimuths."""
    from flexsheet.fem.reference.snapshot_build import (
        build_table,
        load_or_build,
        pack_table,
        reusable_table,
        reused_azimuths,
    )

    spec = RM.RefSpec(0.016, 0.012, 0.012, half_z=True, path_depth=0.012, cut=True)
    grid = SnapshotGrid(angles_deg=(0.0, 10.0, 20.0), depth_max=0.005, depth_step=0.0025, dtheta_deg=5.0,
                        dy=0.005, drho=0.005)
    asked: list[float] = []
    whole = build_table(grid, spec, MAT, 0.008, solved=lambda a, m, d: _linear_states(m, a, d, asked))
    assert asked == [0.0, 10.0, 20.0] and np.abs(whole["side"]).max() > 1e-3 and not whole["reused"].any()
    base_grid = replace(grid, angles_deg=(0.0, 20.0))
    base = {k: (v[[0, 2]] if isinstance(v, np.ndarray) and v.ndim and len(v) == 3 and k not in
                ("theta", "y", "rho", "center", "depths") else v) for k, v in whole.items()}
    base = pack_table(base)[0]
    cache = ArrayCache(str(tmp_path / "cache"), shipped_dir=str(tmp_path / "data"))
    cache.ship("snapshots", _table_key(base_grid, spec), base)
    found = reusable_table(cache, grid, spec, MAT, 0.008,
                           previous=((0.0, 10.0, 20.0), (0.0, 30.0), (0.0, 20.0)))
    assert found is not None and np.allclose(np.degrees(found["angles"]), [0.0, 20.0])
    assert reusable_table(cache, grid, spec, MAT, 0.008, previous=((0.0, 30.0),)) is None
    asked.clear()
    ext = build_table(grid, spec, MAT, 0.008, solved=lambda a, m, d: _linear_states(m, a, d, asked),
                      reuse=found)
    assert asked == [10.0] and ext["reused"].tolist() == [True, False, True]
    assert (reused_azimuths(ext) == {0.0, 20.0} and reused_azimuths(whole) == set()
            and reused_azimuths(base) == set())
    assert np.array_equal(ext["side"][1], whole["side"][1]) and np.array_equal(ext["cap"][1], whole["cap"][1])
    for f in ("side", "cap"):
        diff = np.abs(ext[f] - whole[f]).max()
        assert 0.0 < diff <= 2.0 ** -16, (f, diff)                   # float16 at 0 and 20 deg only
    assert np.array_equal(ext["force"], whole["force"]) and np.array_equal(ext["newton"], whole["newton"])
    # through load_or_build: stored under the three-azimuth key, then found there without solving
    z, hit, _ = load_or_build(cache, grid, spec, MAT, 0.008, solved=lambda a, m, d: _linear_states(m, a, d),
                              reuse=found)
    assert not hit and load_or_build(cache, grid, spec, MAT, 0.008, build=False)[1]
    other = replace(grid, dtheta_deg=2.5)
    with pytest.raises(ValueError, match="theta"):
        build_table(other, spec, MAT, 0.008, solved=lambda a, m, d: _linear_states(m, a, d), reuse=found)
    with pytest.raises(ValueError, match="E "):
        build_table(grid, spec, Material(2e4, MAT.nu), 0.008, solved=lambda a, m, d: _linear_states(m, a, d),
                    reuse=found)


def _table_key(grid, spec):
    from flexsheet.fem.snapshots import table_key

    return table_key(grid, spec, MAT.nu, 0.008, Jm=MAT.Jm)
