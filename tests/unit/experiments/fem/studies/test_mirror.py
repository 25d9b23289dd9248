"""The mirror study (flexsheet/experiments/fem/studies/mirror.py) on the quick run's cache: the half model's
force and asymmetry, and the stability check's lowest eigenvalues of each symmetry block."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = str(Path(__file__).resolve().parents[5])

# the first test of the package's quick run sets it up (conftest.py: a subprocess of several minutes cold,
# timeout 1500 s in _run): pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def test_mirror_study_solves_azimuth_0_without_the_mirror_plane_and_measures_its_asymmetry(quick):
    """The mirror study's half model (no z mirror plane; cut: nodes on that plane, as every off-axis push is
    meshed) at azimuth 0: about twice the quarter model's DOF, the quarter model's force at every depth (3 %:
    the symmetry factors agree, and the cut half mesh is as stiff as the quarter one), and an asymmetry
    measure that reads 0 on the quarter model (symmetric by construction) and not on the half model.
    ``--mirror-study`` alone writes the same study from the cache."""
    from dataclasses import replace

    from flexsheet.experiments.fem.studies.mirror import mirror_asymmetry
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.paths import reference_path
    from flexsheet.fem.reference.settings import settings_for
    from flexsheet.fem.visible_error import realtime_model

    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    with open(base / "out" / "mirror_study.json") as fh:
        ms = json.load(fh)
    (row,) = ms["half_levels"]
    same = conv["levels"][0]          # the quick run's half model: the coarse level's h_fine (12 mm), cut
    assert row["h_fine_m"] == same["h_fine_m"] and row["spec"]["half_z"] is False and row["newton_converged"]
    assert row["spec"]["cut"] is True
    assert 1.4 < row["dofs"] / same["dofs"] < 2.2, (row["dofs"], same["dofs"])
    assert row["quarter_same_h_force_N"] == pytest.approx(same["force_N"])
    # cut, the half model has the quarter model's force at every depth (uncut, a quick run: +5 % at
    # 5 mm, +12 % at 50 mm; cut at 9 mm: within 1.1 %; at 12 mm: within 0.6 %)
    assert row["force_N"] == pytest.approx(same["force_N"], rel=0.03)
    assert len(row["asymmetry_mm"]) == len(ms["depths_m"]) and max(row["asymmetry_mm"]) > 0.1
    assert row["diff_vs_finest_quarter_mm"][0] > 0
    assert os.path.getsize(base / "out" / "mirror_study.png") > 5000
    # the instrument: on the quarter model's own path it reads 0 (u_dof is float32: 1e-5 m is
    # rounding); on the half model a uniform field u = (0, 0, a) is read as |a - (-a)| = 2a
    st, mat = settings_for(True), Material()
    rm = realtime_model(st, mat, str(base / "cache"))
    depths = np.array(ms["depths_m"])
    cache = ArrayCache(str(base / "cache"))
    q = reference_path(st.levels[-1], 0.0, depths, mat, cache, rm.rest_vertices.astype(float), st.contact)
    assert max(mirror_asymmetry(q, st.levels[-1], depths, mat, rm)) < 1e-5
    half = replace(st.levels[0], half_z=False, cut=True)   # the study's own half model, cached by the run
    h = reference_path(half, 0.0, depths, mat, cache, rm.rest_vertices.astype(float), st.contact)
    a = 0.003
    uni = {"u_dof": np.broadcast_to([0.0, 0.0, a], h["u_dof"][:1].shape).astype(np.float32),
           "u": np.broadcast_to([0.0, 0.0, a], h["u"][:1].shape)}
    assert mirror_asymmetry(uni, half, depths[:1], mat, rm)[0] == pytest.approx(2 * a, rel=1e-5)
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf",
                        "--mirror-study", "--out",
                        str(base / "mirror"), "--cache-dir", str(base / "cache")], cwd=ROOT,
                       capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    with open(base / "mirror" / "mirror_study.json") as fh:
        alone = json.load(fh)
    assert alone == ms and os.path.getsize(base / "mirror" / "mirror_study.png") > 5000
    assert not os.path.exists(base / "mirror" / "summary.json")


def test_mirror_stability_finds_the_lowest_eigenvalues_of_each_symmetry_block(quick):
    """The stability check's shift-invert eigenvalues are the lowest of the symmetric and antisymmetric blocks
    of the quarter model's tangent (dense ``eigvalsh`` on the coarse quick mesh agrees to 1e-6), its positive-
    definite verdict agrees with the sign of the lowest eigenvalue, and each converged state's free residual
    is small against the finger force. The blocks: on the z plane the symmetric one frees u_x, u_y and the
    antisymmetric one u_z only; the support is fixed in both."""
    from dataclasses import replace

    import scipy.linalg

    from flexsheet.experiments.fem.studies.mirror import mirror_blocks, mirror_stability
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.capsule_contact import capsule_at
    from flexsheet.fem.reference.paths import push_depths, reference_model, reference_path
    from flexsheet.fem.reference.settings import FINGER_R, settings_for
    from flexsheet.fem.visible_error import realtime_model

    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    with open(base / "out" / "mirror_study.json") as fh:
        stab = json.load(fh)["stability"]
    assert [r["h_fine_m"] for r in stab] == [lv["h_fine_m"] for lv in conv["levels"][-2:]]
    for r in stab:
        assert len(r["anti_N_per_m"]) == len(r["depths_m"]) == len(r["anti_positive_definite"])
        assert all(v > 0 for v in r["sym_N_per_m"])
        assert r["anti_positive_definite"] == [v > 0 for v in r["anti_N_per_m"]]
        assert max(r["residual_N"]) < 1e-3 * max(conv["levels"][-1]["force_N"])
    st, mat = settings_for(True), Material()
    spec = st.levels[0]
    rm = realtime_model(st, mat, str(base / "cache"))
    depths = push_depths(st.depth_step)
    p = reference_path(spec, 0.0, depths, mat, ArrayCache(str(base / "cache")),
                       rm.rest_vertices.astype(float),
                         st.contact)
    j = len(depths) // 2
    got = mirror_stability({"u_dof": p["u_dof"][j:j + 1]}, spec, depths[j:j + 1], mat)
    m = reference_model(spec, 0.0, mat)
    sym, anti = mirror_blocks(m)
    on_z = np.abs(m.points[:, 2] - m.mesh.center[2]) < 1e-9
    inner = on_z & ~m.support & (np.abs(m.points[:, 1] - m.mesh.center[1]) > 1e-9)
    assert inner.any() and not sym[inner][:, :2].any() and sym[inner][:, 2].all()
    assert anti[inner][:, :2].all() and not anti[inner][:, 2].any()
    assert sym[m.support].all() and anti[m.support].all()
    _, K = m.residual_tangent(p["u_dof"][j].astype(float),
                              capsule_at(0.0, float(depths[j]), FINGER_R, m.mesh.radius,
                                         m.mesh.center), m.penalty())
    for name, fixed in (("sym_N_per_m", sym), ("anti_N_per_m", anti)):
        fr = np.flatnonzero(~fixed.ravel())
        lo = scipy.linalg.eigvalsh(K[fr][:, fr].toarray(), subset_by_index=[0, 0])[0]
        assert got[name][0] == pytest.approx(lo, rel=1e-6), name
    with pytest.raises(ValueError, match="quarter model"):
        mirror_stability(p, replace(spec, half_z=False), depths, mat)
    with pytest.raises(ValueError, match="frictionless"):
        mirror_stability(p, spec, depths, mat, contact="sticking")
