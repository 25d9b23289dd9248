"""FEM solver: patch test, rigid modes, condensed == full, convergence, symmetry, zero depth, bad input."""

import math

import numpy as np
import pytest

from flexsheet.fem.choose import Choice, choose
from flexsheet.fem.contact import finger_at, finger_from_tip, imposed_displacement
from flexsheet.fem.corotational import solve_corotational
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, cylinder_tet_mesh
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.solver import CapacitanceSolver, FemModel, solve_full
from flexsheet.fem.sparse_factor import factor

MAT = Material()
COARSE = MeshSpec(0.012, 0.006, 0.012)


@pytest.fixture(scope="module")
def mesh():
    return cylinder_tet_mesh(COARSE)


@pytest.fixture(scope="module")
def p1(mesh):
    return FemModel(mesh, MAT, order=1)


@pytest.fixture(scope="module")
def p2(mesh):
    return FemModel(mesh, MAT, order=2)


def test_mesh_is_closed_outward_and_supported_on_back_half(mesh):
    p = mesh.points[mesh.faces]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    exact = math.pi * mesh.radius ** 2 * mesh.length
    assert 0.97 * exact < vol < exact          # outward winding gives the (faceted) volume, positive
    assert np.all(mesh.points[mesh.fixed, 0] <= mesh.center[0] + 1e-9)
    assert mesh.fixed.sum() > 20
    # every edge of a closed surface is shared by exactly two triangles
    e = np.sort(np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_mesh_spec_rejects_bad_values():
    with pytest.raises(ValueError, match="h_fine"):
        MeshSpec(0.005, 0.01, 0.01)
    with pytest.raises(ValueError, match="^h must"):
        MeshSpec(float("nan"), 0.001, 0.0)
    with pytest.raises(ValueError, match="nu"):
        Material(1e4, 0.5)


@pytest.mark.parametrize("order", [1, 2])
def test_rigid_body_modes_are_in_the_kernel(order, p1, p2):
    m = p1 if order == 1 else p2
    x = m.points
    modes = [np.tile(e, (len(x), 1)) for e in np.eye(3)]
    for axis in np.eye(3):
        modes.append(np.cross(axis, x - x.mean(axis=0)))
    scale = abs(m.K).max() * np.abs(x).max()
    for mode in modes:
        u = np.zeros(m.n_dofs)
        u[m.dofs] = mode
        assert np.abs(m.K @ u).max() < 1e-9 * scale


@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_linear_field_is_reproduced(order, p1, p2):
    m = p1 if order == 1 else p2
    A = np.array([[1e-3, 2e-3, -1e-3], [0.5e-3, -1e-3, 3e-3], [2e-3, 0.0, 1e-3]])
    exact = m.points @ A.T
    bd = m.dofs[m.boundary].ravel()
    inner = np.setdiff1d(np.arange(m.n_dofs), bd)
    x = np.zeros(m.n_dofs)
    x[bd] = exact[m.boundary].ravel()
    x[inner] = factor(m.K[inner][:, inner]).solve(-(m.K[inner][:, bd] @ x[bd]))
    assert np.abs(x[m.dofs] - exact).max() < 1e-9 * np.abs(exact).max()


@pytest.mark.parametrize("order", [1, 2])
def test_condensed_equals_full_solve(order, p1, p2):
    m = p1 if order == 1 else p2
    out = m.boundary & ~m.fixed
    cand = out & (np.linalg.norm(m.points - np.array([0.0, 0.0, 0.0]), axis=1) < 0.016)
    cap = CapacitanceSolver(m, cand, out)
    for angle, depth, axial in [(0.0, 0.004, 0.0), (0.15, 0.012, 0.003)]:
        fg = finger_at(angle, depth, 0.008, m.mesh.radius, m.mesh.center, axial)
        full = solve_full(m, fg)
        fast = cap.solve(fg)
        ref = full.u[np.flatnonzero(out)]
        assert fast.n_contact == full.n_contact > 0
        assert np.abs(fast.u - ref).max() <= 1e-9 * np.abs(ref).max()
        assert abs(fast.force - full.force) <= 1e-9 * full.force
        assert abs(fast.stiffness - full.stiffness) <= 1e-9 * full.stiffness


def test_capacitance_matrix_is_reciprocal(p1):
    """Maxwell–Betti: the Green's function block is symmetric before it is symmetrised."""
    m = p1
    out = m.boundary & ~m.fixed
    cand = out & (np.linalg.norm(m.points, axis=1) < 0.014)
    cap = CapacitanceSolver(m, cand, cand)
    G = cap.G_co            # rows: unit force on a candidate DOF, columns: response at the candidate DOFs
    assert np.abs(G - G.T).max() < 1e-9 * np.abs(G).max()


def test_force_is_mirror_symmetric_and_normal(mesh, p1, p2):
    """Mirroring the mesh z -> -z and the push angle gives the same force (exactly); on one unstructured mesh
    the +/- angle forces of the P2 model agree within 5 %, and a central push has no lateral force."""
    from flexsheet.fem.mesh import finish_cylinder_mesh

    mirrored = finish_cylinder_mesh(mesh.points * np.array([1.0, 1.0, -1.0]), mesh.tets, mesh.radius, mesh.length,
                                    mesh.center, mesh.spec)
    pm = FemModel(mirrored, MAT, order=1)
    a = solve_full(p1, finger_at(0.3, 0.006, 0.008, mesh.radius, mesh.center))
    b = solve_full(pm, finger_at(-0.3, 0.006, 0.008, mesh.radius, mesh.center))
    assert abs(a.force - b.force) < 1e-9 * a.force
    assert abs(a.force_vec[2] + b.force_vec[2]) < 1e-9 * a.force
    F = [solve_full(p2, finger_at(s * 0.3, 0.01, 0.008, mesh.radius, mesh.center)).force for s in (-1, 1)]
    assert abs(F[0] - F[1]) < 0.05 * F[0]
    fg0 = finger_at(0.0, 0.006, 0.008, mesh.radius, mesh.center)
    s0 = solve_full(p2, fg0)
    lateral = np.linalg.norm(s0.force_vec - (s0.force_vec @ fg0.direction) * fg0.direction)
    assert s0.force > 0 and lateral < 0.1 * s0.force


def test_zero_depth_gives_zero_force(p1):
    m = p1
    fg = finger_at(0.2, 0.0, 0.008, m.mesh.radius, m.mesh.center)
    s = solve_full(m, fg)
    assert s.force == 0.0 and s.n_contact == 0 and np.abs(s.u).max() == 0.0
    fg = finger_from_tip(np.array([0.01, 0.0, 0.0]), 0.008, m.mesh.radius, m.mesh.length, m.mesh.center, 0.06)
    assert fg.depth == 0.0 and not imposed_displacement(m.points, fg)[0].any()


def test_force_grows_with_depth_and_is_linear_for_fixed_contact_set(p1):
    m = p1
    F = [solve_full(m, finger_at(0.0, d, 0.008, m.mesh.radius, m.mesh.center)).force for d in (0.002, 0.004, 0.008)]
    assert F[0] < F[1] < F[2]


def test_convergence_with_refinement():
    """Strain energy under a mesh-independent imposed displacement decreases toward the P2 value."""
    def energy(spec, order):
        mesh = cylinder_tet_mesh(spec)
        m = FemModel(mesh, MAT, order=order)
        face = m.boundary & (m.points[:, 1] > mesh.length / 2 - 1e-9) & ~m.fixed
        bd = np.union1d(m.fixed_dofs, m.dofs[face].ravel())
        x = np.zeros(m.n_dofs)
        x[m.dofs[face, 0]] = 1e-3 * (m.points[face, 0] - mesh.center[0]) / mesh.radius
        inner = np.setdiff1d(np.arange(m.n_dofs), bd)
        x[inner] = factor(m.K[inner][:, inner]).solve(-(m.K[inner][:, bd] @ x[bd]))
        return 0.5 * x @ (m.K @ x)

    e16, e12 = energy(MeshSpec(0.016, 0.016, 0.0), 1), energy(MeshSpec(0.012, 0.012, 0.0), 1)
    ref = energy(MeshSpec(0.012, 0.012, 0.0), 2)
    assert e16 > e12 > ref > 0
    assert (e12 - ref) < (e16 - ref)


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
    """The cylinder's update runs the condensed solve in float32 and checks only the monitor tets near the finger
    (as the scenes' does): displacements within 1 µm of the float64 solver of the cached (float64) Green's
    functions, and the same largest strain and inverted count as checking every monitor tet, at depths where
    linear is valid and where it inverts elements, with the near set leaving tets out where it inverts."""
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
            assert np.allclose(fg.center + fg.direction * (fg.radius - fg.depth), fg.contact_point, atol=1e-12)
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


def test_corotational_matches_linear_at_small_depth(p1):
    fg = finger_at(0.0, 0.001, 0.008, p1.mesh.radius, p1.mesh.center)
    lin = solve_full(p1, fg)
    co, it, conv = solve_corotational(p1, fg)
    assert conv and it < 30
    assert abs(co.force - lin.force) < 0.03 * lin.force
    assert np.abs(co.u - lin.u).max() < 0.03 * np.abs(lin.u).max()


def test_choose_takes_cheapest_meeting_target():
    def entry(h, hf, order, dofs, err):
        return {"spec": {"h": h, "h_fine": hf, "refine_radius": 0.012, "arc_deg": 0.0}, "order": order,
                "mesh_nodes": dofs // 3, "dofs": dofs, "surface_error_m": {"0.0050": err / 2, "0.0300": err}}

    table = {"nu": 0.45, "finger_radius": 0.008, "candidates": [
        entry(0.012, 0.006, 1, 1000, 0.003), entry(0.012, 0.004, 2, 9000, 0.0006),
        entry(0.010, 0.004, 2, 15000, 0.0005), entry(0.008, 0.003, 1, 4000, 0.0009)]}
    ch = choose(table, 0.0007, 0.005, 0.03, 0.45, 0.008)
    assert isinstance(ch, Choice) and ch.met and ch.order == 2 and ch.spec.h_fine == 0.004 and ch.spec.h == 0.012
    ch = choose(table, 0.001, 0.005, 0.03, 0.45, 0.008)
    assert ch.met and ch.order == 1 and ch.spec.h == 0.008
    ch = choose(table, 0.0001, 0.005, 0.03, 0.45, 0.008)
    assert not ch.met and ch.spec.h == 0.010
    assert not choose(table, 0.0007, 0.005, 0.03, 0.3, 0.008).met      # table made for another nu
    with pytest.raises(ValueError, match="target"):
        choose(table, -1.0, 0.0, 0.03, 0.45, 0.008)


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


def test_shipped_table_gives_a_choice_meeting_the_default_target():
    from flexsheet.fem.choose import load_table

    ch = choose(load_table(), 0.0007, 0.005, 0.03, MAT.nu, 0.008)
    assert ch.met and ch.error <= 0.0007


def test_mesh_round_trips_through_meshio(mesh, tmp_path):
    import meshio

    from flexsheet.fem.mesh import write_mesh

    path = str(tmp_path / "cyl.vtu")
    write_mesh(mesh, path)
    back = meshio.read(path)
    assert np.allclose(back.points, mesh.points)
    assert np.array_equal(back.cells_dict["tetra"], mesh.tets)
    assert np.array_equal(back.point_data["fixed"].astype(bool), mesh.fixed)


def test_cholesky_solves_spd_systems_and_refuses_an_indefinite_matrix_without_keeping_it():
    """The one sparse Cholesky (CHOLMOD via scikit-sparse) of the linear model and of the nonlinear reference:
    it solves an SPD system (one and several right-hand sides) to rounding, and an indefinite matrix is a
    NotPositiveDefinite error, which the reference reads as "take the projected tangent" (None)."""
    import scipy.sparse as sp

    from flexsheet.fem.reference.newton import cholesky_or_none
    from flexsheet.fem.sparse_factor import NotPositiveDefinite, factor

    n = 400
    lap = sp.diags([-np.ones(n - 1), 2.05 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    b = np.random.default_rng(3).standard_normal((n, 2))
    x = factor(lap, "cholmod").solve(b)
    assert np.abs(lap @ x - b).max() < 1e-10
    assert np.allclose(factor(lap, "cholmod").solve(b[:, 0]), x[:, 0], atol=1e-12)
    assert np.allclose(factor(lap, "superlu").solve(b[:, 0]), x[:, 0], atol=1e-10)
    bad = (lap - 0.2 * sp.identity(n)).tocsr()          # smallest eigenvalue 0.05 - 0.2 < 0
    with pytest.raises(NotPositiveDefinite) as err:
        factor(bad, "cholmod")
    assert err.value.__context__ is None and err.value.__cause__ is None     # nothing refers to the failed factor
    assert cholesky_or_none(bad) is None
    fac = cholesky_or_none(lap)
    assert np.abs(lap @ fac.solve(b[:, 1]) - b[:, 1]).max() < 1e-10
    with pytest.raises(ValueError, match="backend"):
        factor(lap, "mumps")
