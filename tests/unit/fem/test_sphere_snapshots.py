"""The sphere scene's nonlinear table (flexsheet/fem/sphere_snapshots.py): its symmetry frame, the
rotate-and-blend look-up on a field known in closed form, and the symmetry it rests on checked in the FEM
itself."""

import math

import numpy as np
import pytest

from flexsheet.fem.reference.sphere_build import assemble_table, solve_alpha
from flexsheet.fem.sphere_snapshots import SphereGrid, SphereSnapshotModel, grid_points, sphere_frame
from flexsheet.model.scenes import SCENES_DIR, load_scene

SPHERE = SCENES_DIR / "sphere.yaml"


WIDTH = 0.05          # the analytic dent's angular width parameter (1 − cos γ), ~18°


def _dent(points, c, n, d):
    """A displacement field that every rotation about the centre carries into itself: −d·w(p̂·n)·n with w =
    exp(−(1 − p̂·n)/WIDTH), (k, 3) m at ``points`` (k, 3) on a sphere of centre ``c`` for a push with outward
    normal ``n`` at depth ``d``."""
    ph = points - c
    ph = ph / np.linalg.norm(ph, axis=1, keepdims=True)
    return -d * np.exp(-(1.0 - ph @ n) / WIDTH)[:, None] * n[None, :]


def _table(fr, grid):
    pts = grid_points(fr, grid)
    nt, nph = len(grid.thetas()), len(grid.phis())
    per = []
    for a in grid.alphas_deg:
        n = fr.direction(math.radians(a))
        field = np.stack([_dent(pts, fr.center, n, d).reshape(nt, nph, 3) for d in grid.depths()])
        per.append({"field": field.astype(np.float32),
                    "force": grid.depths() ** 1.5 * (1.0 + math.radians(a)),
                    "max_strain": grid.depths() * 10.0, "inverted": np.zeros(len(grid.depths()), np.int64)})
    return assemble_table(fr, grid, per, 1e4)


def test_the_look_up_rotates_a_rotation_equivariant_field_exactly():
    """On a field every rotation about the centre maps into itself, rotate-and-blend must give the field of
    any push — held-out polar angles and any rotation ψ about the support axis — up to the 1° grid's
    interpolation; a look-up that turned the wrong way about the support axis (ψ's sign) reads millimetres.
    Force and dF/dd are the table's bilinear values and their slope."""
    sc = load_scene(SPHERE)
    fr = sphere_frame(sc)
    grid = SphereGrid(depth_max=0.01, depth_step=0.005)
    tab = _table(fr, grid)
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs = dirs[dirs[:, 0] > 0.05]                                     # the free front half
    verts = fr.center + fr.radius * dirs
    sm = SphereSnapshotModel(tab, verts, E=2e4)
    worst = 0.0
    for _ in range(12):
        alpha, psi, d = (math.radians(rng.uniform(0, 60)), rng.uniform(-math.pi, math.pi),
                         rng.uniform(0.001, 0.01))
        n = (math.cos(alpha) * fr.axes[0]
             + math.sin(alpha) * (math.cos(psi) * fr.axes[1] + math.sin(psi) * fr.axes[2]))
        assert sm.covers(n, d)
        u, f, k, strain, inv = sm.surface(n, d)
        worst = max(worst, float(np.abs(u - _dent(verts, fr.center, n, d)).max() / d))
        ia = min(int(math.degrees(alpha) // 10), 5)
        wa = (math.degrees(alpha) - 10 * ia) / 10
        fa = [(1 - wa) * (1 + math.radians(10 * ia)) + wa * (1 + math.radians(10 * ia + 10))]
        jd = 0 if d < 0.005 else 1
        wd = (d - 0.005 * jd) / 0.005
        f_exp = 2.0 * fa[0] * ((1 - wd) * (0.005 * jd) ** 1.5 + wd * (0.005 * (jd + 1)) ** 1.5)  # E 2e4 / 1e4
        assert f == pytest.approx(f_exp, rel=1e-9)
        assert (k
                == pytest.approx(2.0 * fa[0] * ((0.005 * (jd + 1)) ** 1.5 - (0.005 * jd) ** 1.5) / 0.005,
                                 rel=1e-9))
        assert strain == pytest.approx(10 * d, rel=1e-9) and inv == 0
        # the wrong turn about the support axis: the dent lands where the push is not
        if abs(math.sin(alpha) * math.sin(psi)) > 0.3:
            m = math.cos(alpha) * fr.axes[0] + math.sin(alpha) * (math.cos(psi) * fr.axes[1]
                                                                  - math.sin(psi) * fr.axes[2])
            assert np.abs(sm.surface(m, d)[0] - _dent(verts, fr.center, n, d)).max() > 0.3 * d
    assert worst < 0.01, worst                     # of the depth (measured 0.14 %): 1° cells, ~18°-wide dent
    n60 = fr.direction(math.radians(61.0))
    assert not sm.covers(n60, 0.005) and not sm.covers(fr.direction(0.1), 0.0)
    assert not sm.covers(fr.direction(0.1), 0.0101)


def test_sphere_frame_names_what_breaks_the_symmetry():
    sc = load_scene(SPHERE)
    fr = sphere_frame(sc)
    assert (np.allclose(fr.axes, [[1, 0, 0], [0, 0, 1], [0, -1, 0]])
            and fr.radius == pytest.approx(0.025 * 2 ** 0.5))
    a, psi = fr.angles_of(fr.direction(0.3))
    assert a == pytest.approx(0.3) and psi == pytest.approx(0.0, abs=1e-12)
    for name, word in (("cylinder.yaml", "object.kind"), ("organ.yaml", "object.kind"),
                       ("rounded_box.yaml", "object.kind")):
        with pytest.raises(ValueError, match=word):
            sphere_frame(load_scene(SCENES_DIR / name))
    bad = sc.model_copy(update={"support": sc.support.model_copy(update={"kind": "half_space"})})
    with pytest.raises(ValueError, match="support.kind"):
        sphere_frame(bad)
    with pytest.raises(ValueError, match="alphas_deg"):
        SphereGrid(alphas_deg=(10.0, 0.0))
    with pytest.raises(ValueError, match="alpha_deg"):
        solve_alpha(sc, 95.0, SphereGrid())


def test_the_support_axis_symmetry_holds_in_the_fem():
    """What the table rests on, checked in the FEM rather than assumed: a push at 20° in the stroke plane
    (x–z), turned by ψ = 90° about the support axis (+x) into the x–y plane and solved there on its own mesh,
    equals the stroke-plane table's answer turned by ψ; both are coarse meshes (h_fine 12 mm), so they differ
    by their meshing, a small share of the displacement; a table read without the turn (the dent in the wrong
    plane) is off by about the depth."""
    from flexsheet.fem.material import Material
    from flexsheet.fem.mesh import MeshSpec
    from flexsheet.fem.reference.capsule_contact import Capsule
    from flexsheet.fem.reference.hyperelastic import HyperelasticModel
    from flexsheet.fem.reference.path_solver import solve_path_capsule
    from flexsheet.fem.scene_mesh import scene_mesh

    sc = load_scene(SPHERE)
    fr = sphere_frame(sc)
    grid = SphereGrid(alphas_deg=(0.0, 20.0), depth_max=0.006, depth_step=0.006, dtheta_deg=2.0, dphi_deg=2.0)
    spec = (0.016, 0.012, 0.015, 0.02)
    tab = assemble_table(fr, grid, [solve_alpha(sc, a, grid, spec) for a in grid.alphas_deg], sc.material.E)
    n = math.cos(math.radians(20)) * fr.axes[0] + math.sin(math.radians(20)) * fr.axes[2]   # ψ = 90°
    q = fr.center + fr.radius * n
    sm_ = scene_mesh(sc, MeshSpec(*spec[:3]), refine_at=q[None] - np.arange(0, 0.0201, 0.005)[:, None] * n)
    mat = Material.of_scene(sc.material)
    m0 = HyperelasticModel(sm_.mesh, mat, sym_y=False, sym_z=False)
    model = HyperelasticModel(sm_.mesh, mat, sym_y=False, sym_z=False, support=m0.dof_points(sm_.mesh.fixed))
    r = sc.finger.radius
    st = solve_path_capsule(model, lambda d: Capsule(q - d * n + r * n, -n, r), [0.006], step=0.006,
                            iters=60)[0]
    assert st.converged
    dirs = np.array([[np.cos(t) * np.cos(p), np.sin(p), np.cos(p) * np.sin(t)]
                     for t in np.radians(np.arange(-70, 71, 10)) for p in np.radians(np.arange(-70, 71, 10))])
    verts = fr.center + fr.radius * dirs
    direct = np.asarray(model.probe_matrix(verts) @ st.u)
    sm = SphereSnapshotModel(tab, verts)
    u, f, *_ = sm.surface(n, 0.006)
    far = np.linalg.norm(verts - (q - 0.006 * n), axis=1) > r + 0.002          # outside the footprint
    err = np.abs(u - direct)[far].max()
    assert err < 0.15 * 0.006, err               # measured 0.46 mm (8 % of the depth); unturned 4.6 mm
    assert f == pytest.approx(st.force, rel=0.02)      # measured 0.1 % apart
    unturned = sm.surface(fr.direction(math.radians(20)), 0.006)[0]
    assert np.abs(unturned - direct)[far].max() > 3 * err
