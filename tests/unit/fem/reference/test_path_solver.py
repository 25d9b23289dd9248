"""The reference pushed along a path (flexsheet/fem/reference/path_solver.py): a physical push, convergence
with refinement, the capsule form, sticking contact, halved load steps, the unloading sweep and the stable
states."""

from dataclasses import replace

import numpy as np
import pytest
from test_snapshots import C, R

from flexsheet.fem.material import Material
from flexsheet.fem.reference import capsule_contact as CC
from flexsheet.fem.reference import hyperelastic as H
from flexsheet.fem.reference import mesh as RM
from flexsheet.fem.reference import newton as N
from flexsheet.fem.reference import path_solver as PS

MAT = Material()


def test_solve_path_rejects_bad_depths(quarter):
    for bad in ([-0.001], [float("nan")], [0.02, 0.01], []):
        with pytest.raises(ValueError, match="depths"):
            PS.solve_path(quarter, 0.0, bad, 0.008)
    with pytest.raises(ValueError, match="h_fine"):
        RM.RefSpec(0.01, 0.02)


def test_reference_push_is_physical_at_small_depth(quarter):
    """5 mm push: the force grows with depth, the finger is not penetrated by more than 1 % of the depth,
    no element is inverted, the body moves along the push and is symmetric (full force = 4 × quarter)."""
    st = PS.solve_path(quarter, 0.0, [0.0025, 0.005], 0.008, step=0.0025)
    assert all(s.converged for s in st)
    assert 0 < st[0].force < st[1].force
    assert st[1].inverted == 0 and st[1].min_detF > 0.5
    assert st[1].penetration < 0.01 * 0.005
    tip = np.argmin(np.linalg.norm(quarter.points - np.array([0.0, 0.0, 0.0]), axis=1))
    assert abs(st[1].u[tip, 0] + 0.005) < 0.0005                      # the surface point under the finger
    assert abs(st[1].force_vec[1]) < 1e-12 and abs(st[1].force_vec[2]) < 1e-12


def test_reference_converges_with_refinement_at_moderate_depth():
    """Visible-surface difference to the finest of three meshes falls with refinement (10 and 20 mm pushes);
    at 20 mm no element is inverted, at the quadrature points nor at the element nodes."""
    from flexsheet.fem.choose import visible_mask
    from flexsheet.fem.contact import finger_at
    from flexsheet.fem.reference.snapshot_build import folded_probe, unfolded_sample

    th = np.radians(np.linspace(-80, 80, 33))
    ys = np.linspace(0.0, 0.05, 11)
    T, Y = np.meshgrid(th, ys, indexing="ij")
    pts = np.column_stack([C[0] + R * np.cos(T.ravel()), Y.ravel(), C[2] + R * np.sin(T.ravel())])
    out = []
    for hf in (0.008, 0.0057, 0.004):
        m = H.HyperelasticModel(RM.reference_mesh(RM.RefSpec(0.016, hf, 0.018, True), 0.0), MAT, True, True)
        st = PS.solve_path(m, 0.0, [0.01, 0.02], 0.008, step=0.005)
        assert all(s.converged for s in st)
        out.append([unfolded_sample(folded_probe(m, pts), s.u, pts, m) for s in st])
    assert st[-1].inverted == 0 and st[-1].min_detF > 0
    for j, d in enumerate((0.01, 0.02)):
        vis = visible_mask(pts, finger_at(0.0, d, 0.008, R, C))
        e = [np.linalg.norm(out[i][j] - out[2][j], axis=1)[vis].max() for i in range(2)]
        assert e[1] < e[0], (d, e)
        assert e[1] < 0.0007, (d, e)            # the last refinement moves the visible surface < 1 px


def test_solve_path_capsule_matches_the_cylinder_path(quarter):
    """The callable-finger variant reproduces the azimuth form for the same finger; refuses a non-callable."""
    m = quarter
    a = PS.solve_path(m, 0.0, [0.004], 0.008, step=0.002)
    b = PS.solve_path_capsule(m, lambda d: CC.capsule_at(0.0, d, 0.008, m.mesh.radius, m.mesh.center),
                              [0.004],
                              step=0.002)
    assert a[0].converged and b[0].converged and a[0].force > 0.05
    assert b[0].force == pytest.approx(a[0].force, rel=1e-12)
    assert np.abs(b[0].u - a[0].u).max() <= 1e-12
    with pytest.raises(ValueError, match="capsule"):
        PS.solve_path_capsule(m, 0.0, [0.004])


def test_sticking_push_holds_the_surface_on_the_finger(quarter):
    """8 mm push: the contact points stuck to the finger stay on their finger points (within the penalty's
    elastic give) and move with the finger between 4 and 8 mm, while frictionless the same material points
    slide over the sphere; the stuck surface needs more force (friction stiffens the contact); both converge
    with no inverted element; an unknown law is refused."""
    m = quarter
    fr = PS.solve_path(m, 0.0, [0.004, 0.008], 0.008, step=0.002, contact="frictionless")
    st = PS.solve_path(m, 0.0, [0.004, 0.008], 0.008, step=0.002, contact="sticking")
    for s in fr + st:
        assert s.converged and s.inverted == 0
    assert "anchors" not in fr[1].extra
    assert st[0].force < st[1].force
    assert fr[1].force < st[1].force < 1.5 * fr[1].force
    a = st[1].extra["anchors"]
    stuck = np.isfinite(a[..., 0])
    assert stuck.sum() >= 1
    c4, c8 = (CC.capsule_at(0.0, d, 0.008, m.mesh.radius, m.mesh.center).center for d in (0.004, 0.008))
    on = np.linalg.norm(m._contact_x(st[1].u)[stuck] - c8 - a[stuck], axis=1).max()
    assert on < 5e-5                                                    # held on its finger point
    held = np.isfinite(st[0].extra["anchors"][..., 0])                # stuck already at 4 mm
    assert held.sum() >= 1
    rel = [np.linalg.norm((m._contact_x(s[1].u)[held] - c8) - (m._contact_x(s[0].u)[held] - c4), axis=1).max()
           for s in (fr, st)]  # motion relative to the finger, 4 -> 8 mm
    assert rel[1] < 0.3 * rel[0], rel
    with pytest.raises(ValueError, match="contact"):
        PS.solve_path(m, 0.0, [0.004], 0.008, contact="glued")


def test_load_steps_after_a_halved_step_keep_the_halved_size(quarter, monkeypatch):
    """A step that fails (stagnates: not converged before running out of iterations) is halved and the steps
    after it stay that small (once the path got hard, Newton is not sent back into the 2.5 mm steps that cost
    60 iterations per try on the 3.4 mm mesh at 47.5 mm)."""
    real = N.newton_minimise
    tried = []

    def flaky(model, u, caps, k, iters, tol_u, tol_r, log, state=None, max_step=0.001, shifted=False):
        tried.append(-float(caps.center[0] + caps.radius * caps.direction[0]))   # depth of the tip (x = −d)
        if len(tried) == 2:                                              # the second step fails once
            return u, 3, False
        return real(model, u, caps, k, iters, tol_u, tol_r, log, state, max_step, shifted)

    monkeypatch.setattr(N, "newton_minimise", flaky)
    st = PS.solve_path(quarter, 0.0, [0.002, 0.004, 0.006], 0.008, step=0.002)
    assert all(s.converged for s in st)
    # 2 mm, then 4 mm fails, 3 mm (halved), then 1 mm steps to 6 mm
    assert np.allclose(tried, [0.002, 0.004, 0.003, 0.004, 0.005, 0.006], atol=1e-9), tried
    assert abs(st[-1].depth - 0.006) < 1e-12


def _caps(m, angle=0.0):
    return lambda d: CC.capsule_at(angle, d, 0.008, m.mesh.radius, m.mesh.center)


@pytest.fixture(scope="module")
def loading(quarter):
    return PS.solve_path(quarter, 0.0, [0.004, 0.008, 0.012], 0.008, step=0.004)


def test_unload_sweep_finds_the_loading_path_where_there_is_one_branch(quarter, loading):
    """A push without hysteresis: unloading from the deepest state lands on the loading state at every depth
    (the sweep runs to the shallowest), and the stable branch is the loading path."""
    st = loading
    sw = PS.unload_sweep(quarter, _caps(quarter), st, step=0.002)
    assert [s.depth for s in sw] == pytest.approx([0.004, 0.008, 0.012]) and all(s.converged for s in sw)
    for a, b in zip(sw[:2], st[:2], strict=True):
        assert np.abs(a.u - b.u).max() <= PS.BRANCH_MEET_TOL
        assert abs(a.extra["energy"] - a.extra["energy_loading"]) <= 1e-6 * abs(a.extra["energy"])
    chosen, branch, energies = PS.stable_states(quarter, _caps(quarter), st, step=0.002)
    assert branch.tolist() == [0, 0, 0] and energies.shape == (3, 2)
    assert (np.allclose(energies[:, 0], energies[:, 1], rtol=1e-6)
            and all(c is s for c, s in zip(chosen, st, strict=True)))


def test_stable_states_replaces_a_higher_energy_state_by_the_unloaded_equilibrium(quarter, loading):
    """A loading state that is not the lowest-energy equilibrium at its depth (here the 8 mm state pushed off
    its equilibrium, as a metastable branch would be) is replaced by the state unloading reaches there, which
    is the equilibrium: within 20 µm of the true loading state, at a lower Π. The others stay."""
    st = loading
    bad = list(st)
    X = quarter.points - quarter.mesh.center
    bump = 0.0005 * np.exp(-((X[:, 1] ** 2 + X[:, 2] ** 2) / 0.01 ** 2))[:, None] * np.array([0.0, 0.0, 1.0])
    bad[1] = replace(st[1], u=st[1].u + bump * (X[:, 2:3] > 0))
    chosen, branch, energies = PS.stable_states(quarter, _caps(quarter), bad, step=0.002)
    assert branch.tolist() == [0, 1, 0]
    assert energies[1, 1] < energies[1, 0] and chosen[1].extra["energy"] == energies[1, 1]
    assert np.abs(chosen[1].u - st[1].u).max() < 2e-5
    assert chosen[0] is bad[0] and chosen[2] is bad[2]
    with pytest.raises(ValueError, match="ascending"):
        PS.unload_sweep(quarter, _caps(quarter), st[::-1])
    with pytest.raises(ValueError, match="non-empty"):
        PS.unload_sweep(quarter, _caps(quarter), [])
    stuck = [replace(x, extra={"anchors": np.zeros((1, 1, 3))}) for x in st]
    with pytest.raises(ValueError, match="frictionless"):
        PS.unload_sweep(quarter, _caps(quarter), stuck)
