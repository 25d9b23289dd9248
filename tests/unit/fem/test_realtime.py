"""The cylinder's real-time model (flexsheet/fem/realtime.py): bad fingertips raise and the model keeps
working, the cache, deep pushes flagged, the single-precision update and near checks, sticky contact, the
nonlinear table."""

import numpy as np
import pytest

from flexsheet.fem.contact import finger_at
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.solver import CapacitanceSolver

MAT = Material()


COARSE = MeshSpec(0.012, 0.006, 0.012)


def test_bad_fingertip_raises_and_model_keeps_working(tmp_path):
    rm = RealtimeModel(COARSE, MAT, order=1, cache_dir=str(tmp_path))
    for bad, word in [([np.nan, 0, 0], "finite"), ([-0.01, 0.5, 0.0], "end faces"), ([-0.2, 0, 0], "back"),
                      ([-rm.mesh.radius, 0.0, 0.0], "axis")]:
        with pytest.raises(ValueError, match=word):
            rm.update(np.array(bad, float))
    u = rm.update(np.array([-0.004, 0.0, 0.0]))
    assert u.valid and u.force > 0 and np.all(np.isfinite(u.vertices))
    # cache hit gives the same answer
    rm2 = RealtimeModel(COARSE, MAT, order=1, cache_dir=str(tmp_path))
    assert rm2.cache_hit and not rm.cache_hit
    u2 = rm2.update(np.array([-0.004, 0.0, 0.0]))
    assert np.array_equal(u.vertices, u2.vertices) and u.force == u2.force


def test_deep_push_is_flagged_never_garbage(p1):
    rm = RealtimeModel(COARSE, MAT, order=1, cache_dir=None)
    states = []
    for d in np.arange(0.002, 0.0505, 0.004):
        u = rm.update(np.array([-d, 0.0, 0.0]))
        assert np.all(np.isfinite(u.vertices))
        if not u.valid:
            assert np.array_equal(u.vertices, rm._rest) and u.force == 0.0
        states.append((d, u.status, u.valid, u.max_strain))
    assert states[0][1] == "ok"
    assert any(s[1].startswith("linear_invalid") for s in states)    # 50 mm into a 70 mm cylinder
    strains = [s[3] for s in states]
    assert strains[-1] > strains[0]


def test_single_precision_update_and_near_checks_match_the_full_ones(tmp_path):
    """The cylinder's update runs the condensed solve in float32 and checks only the monitor tets near the
    finger (as the scenes' does): displacements within 1 µm of the float64 solver of the cached (float64)
    Green's functions, and the same largest strain and inverted count as checking every monitor tet, at depths
    where linear is valid and where it inverts elements, with the near set leaving tets out where it
    inverts."""
    rm = RealtimeModel(MeshSpec(0.012, 0.006, 0.012, 60.0), MAT, order=2, cache_dir=str(tmp_path))
    assert rm.solver.G_co.dtype == np.float32
    z = rm.cache.load("capacitance", rm.cache_key)
    assert z is not None and z["G_co"].dtype == np.float64
    s64 = CapacitanceSolver.from_arrays(z)
    tc = rm._tet_checks
    inverted_with_tets_left_out = 0
    for ang in (0.0, -0.8):
        for d in (0.005, 0.02, 0.03, 0.04):
            fg = finger_at(ang, d, 0.008, rm.mesh.radius, rm.mesh.center)
            assert np.allclose(fg.center + fg.direction * (fg.radius - fg.depth), fg.contact_point,
                               atol=1e-12)
            u32, u64 = rm.solver.solve(fg).u, s64.solve(fg).u
            assert np.abs(u32 - u64).max() < 1e-6 and np.abs(u64).max() > 0.5 * d
            near, full = rm._checks(fg, u64), tc(u64)
            assert near[1] == full[1] and near[0] == pytest.approx(full[0], rel=1e-12)
            if full[1] > 0 and not tc.near(fg.contact_point, 0.008 + d + 2 * 0.006).all():
                inverted_with_tets_left_out += 1
    assert inverted_with_tets_left_out > 0          # the check is not vacuous


def test_sticky_contact_holds_direction_past_the_axis():
    rm = RealtimeModel(COARSE, MAT, order=1, max_depth=0.06, cache_dir=None)
    rm.update(np.array([-0.01, 0.0, 0.0]))
    u = rm.update(np.array([-0.045, 0.0, 0.0]))          # beyond the axis (x_O = -35 mm): still a 45 mm push
    assert abs(u.depth - 0.045) < 1e-12


def test_nonlinear_table_replaces_invalid_linear():
    rm = RealtimeModel(COARSE, MAT, order=1, strain_limit=0.05, cache_dir=None)
    rm.build_nonlinear_table(np.array([0.0, 0.004, 0.008]))
    F = rm.nonlinear["F"][0]
    assert F[0] == 0.0 and 0 < F[1] < F[2]
    u = rm.update(np.array([-0.006, 0.0, 0.0]))
    assert u.method == "corotational" and u.status.startswith("nonlinear") and u.valid
    assert abs(u.force - 0.5 * (F[1] + F[2])) < 1e-9 * F[2]
    assert abs(u.stiffness - (F[2] - F[1]) / 0.004) < 1e-6 * u.stiffness
    rm.reset()
    c, r = rm.mesh.center, rm.mesh.radius - 0.006
    off = rm.update(c + r * np.array([np.cos(0.5), 0.0, np.sin(0.5)]))
    assert abs(off.depth - 0.006) < 1e-12
    assert off.method != "corotational"        # the table covers the front centre only (arc_deg = 0)
