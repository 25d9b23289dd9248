"""`flexsheet experiment fem --quick` end to end, cold cache: the report keys, and physics the
neo-Hookean reference must show whatever the mesh (force rising with depth, the Hertz force at a shallow push,
no element inverted at a quadrature point, the nonlinear snapshots beating linear elasticity at 0-50 mm), and
that a second run reads everything from the cache."""

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

ROOT = str(Path(__file__).resolve().parents[3])
# the module's first test sets up the quick run (a subprocess of several minutes cold, timeout 1500 s in _run):
# pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def _run(out, cache):
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf", "--out", str(out),
                        "--cache-dir", str(cache), "--jobs", "2"], cwd=ROOT, capture_output=True, text=True,
                       timeout=1500)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    with open(os.path.join(out, "summary.json")) as fh:
        return json.load(fh), r.stdout


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    base = tmp_path_factory.mktemp("fem")
    summ, log = _run(base / "out", base / "cache")
    return base, summ, log


def test_summary_has_the_issue_keys_with_real_numbers(quick):
    base, s, _ = quick
    rt = s["realtime"]
    assert rt["method"] == "snapshots"
    assert math.isfinite(rt["update_ms"]) and 0 < rt["update_ms"] < 50
    e = rt["max_visible_error_mm_0_50"]
    assert math.isfinite(e) and 0 < e < 5.0
    assert isinstance(s["reference"]["converged"], bool)
    for name in ("convergence", "failure_map", "accuracy_speed"):
        assert os.path.getsize(base / "out" / f"{name}.png") > 5000
        with open(base / "out" / f"{name}.json") as fh:
            assert json.load(fh)


def test_reference_physics(quick):
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    depths = conv["depths_m"]
    assert depths[-1] == pytest.approx(0.05)
    for lv in conv["levels"]:
        f = lv["force_N"]
        assert all(b > a for a, b in zip(f, f[1:], strict=False)), f          # stiffer the deeper, no snap back
        assert max(lv["inverted_qp"]) == 0                                    # the line search keeps det F > 0
        assert lv["newton_converged"]
    # Hertz (Johnson, Contact Mechanics §4.2) at the shallowest push: sphere r = 8 mm on the R = 35.4 mm cylinder
    E, nu, r, R = s["material"]["E"], s["material"]["nu"], s["finger_radius_m"], 0.025 * math.sqrt(2)
    d = depths[0]
    r_eff = math.sqrt(r * (r * R / (r + R)))
    hertz = 4.0 / 3.0 * E / (1 - nu ** 2) * math.sqrt(r_eff) * d ** 1.5
    assert conv["levels"][-1]["force_N"][0] == pytest.approx(hertz, rel=0.25)
    # the coarser mesh differs from the finest, by less than a centimetre on the visible surface
    err = conv["levels"][0]["error_vs_finest_mm"]
    assert 0 < max(err) < 10
    assert max(conv["levels"][-1]["error_vs_finest_mm"]) == 0
    ref = s["reference"]
    assert ref["mesh_converged"] == (ref["monotone_decrease"] and ref["last_refinement_change_mm"] <= 0.35
                                     and ref["finest_newton_converged"] and ref["finest_inverted_qp_max"] == 0)
    assert ref["converged"] == (ref["mesh_converged"] and ref["penalty_study"]["converged"])
    if len(conv["levels"]) < 3:
        assert not ref["converged"]


def test_skin_study_refines_the_surface_layer_only(quick):
    """The skin study's variant is the next-to-finest mesh plus a finer surface layer: more DOF than that mesh,
    Newton converged, a real change of the visible surface at every depth past the first, and a softer push at
    50 mm (finer elements where the finger bends the surface stiffen it less; the full tube refinement does too)."""
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    sk = conv["skin_study"]
    assert sk["unrefined"]["h_fine"] == conv["levels"][-2]["h_fine_m"] and sk["unrefined_dofs"] == conv["levels"][-2]["dofs"]
    (row,) = sk["skins"]
    assert row["spec"]["skin_h"] == 0.005 and row["newton_converged"] and row["dofs"] > sk["unrefined_dofs"]
    ch = np.array(row["change_vs_unrefined_mm"])
    assert ch.shape == (len(sk["depths_m"]),) and np.all(np.isfinite(ch)) and np.all(ch[1:] > 0.01)
    f0, f_fine = sk["unrefined_force_N_at_50mm"], sk["finest_force_N_at_50mm"]
    assert f_fine < f0 and row["force_N_at_50mm"] < f0 - 0.1, (f0, row["force_N_at_50mm"], f_fine)
    assert s["reference"]["skin_study"]["skins"][0]["change_vs_unrefined_mm_at_50mm"] == pytest.approx(ch[-1])


def test_snapshot_mesh_study_tables_the_skin_meshes_and_agrees_with_the_convergence_figure(quick):
    """The snapshot-mesh study builds an azimuth-0 table on the next-to-finest mesh and on its skin variant from
    the cached solves. The base mesh's table error and the convergence study's error of that mesh measure the
    same mesh against the same finest one by different routes (table sampling and depth interpolation against
    direct probing): they agree to 0.2 mm."""
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    ms = s["realtime"]["snapshot_mesh_study"]
    plain, skin = ms["meshes"]
    assert plain["skin_h_m"] == 0.0 and skin["skin_h_m"] == 0.005 and skin["dofs"] > plain["dofs"]
    assert plain["dofs"] == conv["levels"][-2]["dofs"] and skin["cpu_seconds_per_azimuth"] > 0
    level_err = max(conv["levels"][-2]["error_vs_finest_mm"])
    assert level_err > 0.5 and abs(plain["max_visible_error_mm"] - level_err) < 0.2, (plain, level_err)
    assert 0 < skin["max_visible_error_mm"] < 10


def test_mirror_study_solves_azimuth_0_without_the_mirror_plane_and_measures_its_asymmetry(quick):
    """The mirror study's half model (no z mirror plane; cut: nodes on that plane, as every off-axis push is
    meshed) at azimuth 0: about twice the quarter model's DOF, the quarter model's force at every depth (3 %:
    the symmetry factors agree, and the cut half mesh is as stiff as the quarter one), and an asymmetry measure that reads 0 on the quarter model (symmetric
    by construction) and not on the half model. ``--mirror-study`` alone writes the same study from the cache."""
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
    # the instrument: on the quarter model's own path it reads 0 (u_dof is float32: 1e-5 m is rounding); on the half
    # model a uniform field u = (0, 0, a) is read as |a - (-a)| = 2a
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
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf", "--mirror-study", "--out",
                        str(base / "mirror"), "--cache-dir", str(base / "cache")], cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    with open(base / "mirror" / "mirror_study.json") as fh:
        alone = json.load(fh)
    assert alone == ms and os.path.getsize(base / "mirror" / "mirror_study.png") > 5000
    assert not os.path.exists(base / "mirror" / "summary.json")


def test_mirror_stability_finds_the_lowest_eigenvalues_of_each_symmetry_block(quick):
    """The stability check's shift-invert eigenvalues are the lowest of the symmetric and antisymmetric blocks
    of the quarter model's tangent (dense ``eigvalsh`` on the coarse quick mesh agrees to 1e-6), its positive-
    definite verdict agrees with the sign of the lowest eigenvalue, and each converged state's free residual is
    small against the finger force. The blocks: on the z plane the symmetric one frees u_x, u_y and the
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
    p = reference_path(spec, 0.0, depths, mat, ArrayCache(str(base / "cache")), rm.rest_vertices.astype(float),
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
    _, K = m.residual_tangent(p["u_dof"][j].astype(float), capsule_at(0.0, float(depths[j]), FINGER_R, m.mesh.radius,
                                                                      m.mesh.center), m.penalty())
    for name, fixed in (("sym_N_per_m", sym), ("anti_N_per_m", anti)):
        fr = np.flatnonzero(~fixed.ravel())
        lo = scipy.linalg.eigvalsh(K[fr][:, fr].toarray(), subset_by_index=[0, 0])[0]
        assert got[name][0] == pytest.approx(lo, rel=1e-6), name
    with pytest.raises(ValueError, match="quarter model"):
        mirror_stability(p, replace(spec, half_z=False), depths, mat)
    with pytest.raises(ValueError, match="frictionless"):
        mirror_stability(p, spec, depths, mat, contact="sticking")


def test_penalty_study_shows_the_default_penalty_converged(quick):
    """The contact penalty is a discretisation parameter too: a 10× stiffer finger penetrates less and moves the
    visible surface by less than 0.1 mm at the default; the default penetrates the finger by < 0.05 mm at 50 mm
    (the old 10³·E/h penetrated 1.2 mm there)."""
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        pen = json.load(fh)["penalty_study"]
    rows = {r["penalty_scale"]: r for r in pen["scales"]}
    d, stiff = pen["default_scale"], 10 * pen["default_scale"]
    assert set(rows) == {d, stiff}
    assert rows[d]["penetration_mm_at_50mm"] < 0.05
    assert rows[stiff]["penetration_mm_at_50mm"] <= rows[d]["penetration_mm_at_50mm"]
    assert 0 < pen["default_vs_10x_stiffer_mm"] == pytest.approx(max(rows[d]["error_vs_stiffest_mm"]))
    assert pen["converged"] == (pen["default_vs_10x_stiffer_mm"] <= pen["tolerance_mm"] == 0.1)
    assert pen["converged"]
    # a stiffer finger pushes back harder, by little once converged
    assert rows[stiff]["force_N_at_50mm"] == pytest.approx(rows[d]["force_N_at_50mm"], rel=0.01)
    assert all(r["newton_converged"] for r in pen["scales"])


def test_snapshots_beat_linear_elasticity_at_large_push(quick):
    _, s, _ = quick
    assert s["realtime"]["max_visible_error_mm_0_50"] < 0.5 * s["linear"]["max_visible_error_mm_0_50"]
    # between snapshot depths the interpolation adds error; at the snapshot depths only surface sampling is left
    rt = s["realtime"]
    assert rt["max_visible_error_mm_snapshot_depths"] < rt["max_visible_error_mm_held_out_depths"]


def test_second_run_reads_the_cache(quick):
    base, s1, _ = quick
    _, _, log1 = quick
    assert "DOF, load steps" in log1                     # the cold run solved ...
    # ... every reference push in its two prefetch workers (planned_solves lists all the run reads): the run
    # itself started none
    solves = [ln for ln in log1.splitlines() if "DOF, load steps" in ln]
    assert "prefetch: " in log1 and all(ln.startswith("[solver ") for ln in solves), solves
    assert {ln.split("]")[0] for ln in solves} == {"[solver 1", "[solver 2"}
    # the pushes the tables read (the snapshots' and the snapshot-mesh study's three) got their unloading sweep
    # (stable_path) in a worker too
    sweeps = [ln for ln in log1.splitlines() if "unloading from" in ln]
    assert len(sweeps) == 3 and all(ln.startswith("[solver ") for ln in sweeps), sweeps
    s2, log = _run(base / "out2", base / "cache")
    assert "DOF, load steps" not in log and "loaded from cache" in log      # ... the second did not
    assert "unloading from" not in log
    assert s2["realtime"]["precompute_cache_hit"] is True
    assert s2["realtime"]["max_visible_error_mm_0_50"] == pytest.approx(s1["realtime"]["max_visible_error_mm_0_50"],
                                                                        rel=1e-9)
    assert s2["reference"]["levels"] == s1["reference"]["levels"]


def test_fold_study_reads_the_levels_from_the_cache_and_finds_no_fold_on_the_coarse_meshes(quick):
    """--fold-study checks the reference's own surface for folds (it has no self-contact): it reads the quick
    run's cached levels (solving only its tip-refined sequence), and the coarse meshes' visible surface stays smooth (w ≈ ½, nothing inside
    the body) to 50 mm, while the material over the fingertip (footprint included) is kinked at the apex (w > ½)
    and stretched several times over; its differences to the finest level are the convergence study's."""
    base, _, _ = quick
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf", "--fold-study", "--out",
                        str(base / "fold"), "--cache-dir", str(base / "cache"), "--jobs", "2"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    solved = [ln for ln in r.stdout.splitlines() if "DOF, load steps" in ln]
    assert len(solved) == 2 and all(",tip=" in ln for ln in solved), solved     # the tip sequence only
    assert "fold study done" in r.stdout
    with open(base / "fold" / "fold_study.json") as fh:
        fs = json.load(fh)
    assert os.path.getsize(base / "fold" / "fold_study.png") > 5000
    assert fs["depths_mm"] == pytest.approx([5.0 * k for k in range(1, 11)])
    assert [lv["h_fine_mm"] for lv in fs["levels"]] == pytest.approx([12.0, 9.0])
    for lv in fs["levels"]:
        assert max(lv["n_penetrating"]) == 0 and max(lv["max_penetration_mm"]) == 0.0
        assert 0.49 < max(lv["max_winding"]) < 0.6
        fp = lv["with_footprint"]
        assert max(fp["n_penetrating"]) == 0 and fp["max_winding"][-1] > max(lv["max_winding"])
        assert fp["max_stretch"][-1] > 2.0 and lv["min_stretch"][-1] < lv["min_stretch"][0] < 1.0
        assert lv["max_principal_strain"][-1] > lv["max_principal_strain"][0] > 0
    assert fs["fold_free_to_mm"] == 50.0 and fs["first_penetration_mm_by_h_fine_mm"] == {"12.0": None, "9.0": None}
    tip = fs["tip_sequence"]
    assert [(t["h_fine_mm"], t["tip_h_mm"]) for t in tip["levels"]] == pytest.approx([(12.0, 5.0), (9.0, 4.0)])
    assert tip["converged"] is False and "tip_check" not in tip              # two levels cannot converge
    assert max(tip["levels"][-1]["difference_to_finest_mm"]) == 0.0
    assert tip["last_refinement_change_mm"] == pytest.approx(max(tip["levels"][0]["difference_to_finest_mm"]))
    for t, lv in zip(tip["levels"], fs["levels"], strict=True):        # the tip adds elements at the push point
        assert t["dofs"] > lv["dofs"] and t["newton_converged"]
    # the finer apex stretches more: the strain at 50 mm on the tip level exceeds the plain level's
    assert tip["levels"][-1]["max_principal_strain"][-1] > fs["levels"][-1]["max_principal_strain"][-1]
    # azimuth-0 snapshot tables on the next-to-finest plain and tip levels, judged against the finest tip level:
    # the tip-refined table is the closer one at the deep end
    plain, tipped = tip["snapshots"]["tables"]
    assert plain["tip_h_mm"] == 0.0 and tipped["tip_h_mm"] == pytest.approx(5.0) and len(tipped["error_mm"]) == 10
    assert tipped["max_visible_error_mm"] < plain["max_visible_error_mm"]
    assert max(tipped["error_mm"][-3:]) < min(plain["error_mm"][-3:])
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    assert fs["levels"][0]["difference_to_finest_mm"] == pytest.approx(conv["levels"][0]["error_vs_finest_mm"],
                                                                       rel=1e-9)


def test_material_study_gent_stiffens_the_deep_push_only_and_is_judged_against_its_own_finest_level(quick):
    """--material-study: the quick run's neo-Hookean levels come from its cache, only the Gent solid's (Jm 97.2,
    natural rubber) two levels and its table's stable branch are solved. Physics whatever the mesh: Gent is the
    neo-Hookean solid at small strain (the two finest solutions within 0.05 mm at 5 mm) and stiffer where the
    chains stretch (more force, less strain at 50 mm on every level, the distance between the materials growing
    with depth), its strain stays below its own limiting extensibility; the snapshots are judged against the
    finer level, never the one they were sampled from."""
    base, _, _ = quick
    r = subprocess.run([sys.executable, "-m", "flexsheet", "experiment", "fem", "--quick", "--Jm", "inf", "--material-study",
                        "--out", str(base / "material"), "--cache-dir", str(base / "cache"), "--jobs", "2"], cwd=ROOT,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    solved = [ln for ln in r.stdout.splitlines() if "DOF, load steps" in ln]
    assert len(solved) == 2, solved                                      # the Gent levels only
    assert r.stdout.count("unloading from 50 mm") == 1                   # and the Gent table's stable branch
    with open(base / "material" / "material_study.json") as fh:
        ms = json.load(fh)
    assert os.path.getsize(base / "material" / "material_study.png") > 5000
    nh, gent = ms["materials"]
    assert nh["name"] == "neo-Hookean" and nh["Jm"] is None and gent["Jm"] == pytest.approx(97.2)
    for a, b in zip(nh["convergence"]["levels"], gent["convergence"]["levels"], strict=True):
        assert a["dofs"] == b["dofs"] and b["newton_converged"] and max(b["inverted_qp"]) == 0
        assert b["force_N"][-1] > 1.02 * a["force_N"][-1]                 # stiffer at 50 mm
        assert b["force_N"][0] == pytest.approx(a["force_N"][0], rel=0.02)  # the same solid at 5 mm
        assert b["max_strain"][-1] < a["max_strain"][-1]
        assert max(b["max_strain"]) < (97.2 + 2.0) / 2.0                 # I1 - 3 < Jm bounds every stretch
    d = ms["difference_between_materials_mm"]
    assert len(d) == 10 and d[0] < 0.05 and d[-1] > 0.3 and d[-1] > 5 * d[1]
    for row, conv in ((nh, nh["convergence"]), (gent, gent["convergence"])):
        sn = row["snapshots_azimuth0"]
        assert sn["mesh"]["h_fine"] == pytest.approx(0.012) and len(sn["error_mm"]) == 10
        assert min(sn["error_mm"]) > 0                                  # judged against the 9 mm level, not itself
        assert sn["max_visible_error_mm"] == pytest.approx(max(sn["error_mm"]))
        # at 50 mm, a snapshot depth, the table is its own material's 12 mm solve: its error is that level's
        # distance to the 9 mm level (a table of the other material would be ~0.8 mm off it)
        assert sn["error_mm"][-1] == pytest.approx(conv["levels"][0]["error_vs_finest_mm"][-1], abs=0.15)
        assert conv["converged"] is False                                 # two levels cannot converge
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    assert nh["convergence"]["levels"][0]["error_vs_finest_mm"] == pytest.approx(
        conv["levels"][0]["error_vs_finest_mm"], rel=1e-9)


def test_full_settings_judge_the_nodes_snapshot_mesh_against_a_finer_one():
    """The node's snapshot table (DEFAULT_REF_SPEC) is one of the full convergence study's meshes and the
    snapshots the experiment judges are taken on it, against a finer mesh: the accuracy reported is the
    node's, and it includes its mesh's own error. The levels refine by ~1.33 each."""
    from flexsheet.fem.reference.settings import settings_for
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC

    st = settings_for(False)
    lv = st.levels
    assert len(lv) >= 3 and DEFAULT_REF_SPEC in lv and st.snap_spec == DEFAULT_REF_SPEC
    assert lv[-1].h_fine < DEFAULT_REF_SPEC.h_fine
    ratios = [a.h_fine / b.h_fine for a, b in zip(lv[:-1], lv[1:], strict=True)]
    assert all(1.2 < r < 1.45 for r in ratios), ratios
    # every held-out azimuth lies strictly between two snapshot azimuths (interpolated, not a snapshot itself),
    # and the snapshots are no farther apart than the node table's widest interval (10 deg)
    ga = st.grid.angles_deg
    assert st.holdout_deg and all(a not in ga and ga[0] < a < ga[-1] for a in st.holdout_deg)
    # the snapshot azimuths are the node table's, solved at its depth step (its cached paths, not extra solves)
    assert set(ga) <= set(DEFAULT_GRID.angles_deg) and st.fine_step == DEFAULT_GRID.depth_step
    node_widest = max(np.diff(DEFAULT_GRID.angles_deg))
    assert node_widest == 10.0 and max(np.diff(ga)) <= node_widest


def test_planned_solves_list_each_push_the_run_reads_once_by_cache_key():
    """The full run reads 16 distinct reference pushes: five convergence levels, three cut half models, three
    more penalties (the default is level 1's), two skins, azimuth 5 held out and the snapshots' 10 and 20; the
    quick run 5; ``--mirror-study`` the levels and the half models (its stability check reads two levels);
    ``--holdout-study`` the finest level, the snapshot mesh's azimuth-0 level and its cut paths at 5 and 10 only
    (the table's blend at 5 reads 0 and 10, not 20)."""
    from flexsheet.experiments.fem.plan import planned_solves
    from flexsheet.experiments.fem.studies.holdout import holdout_grid
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.paths import push_depths, reference_key
    from flexsheet.fem.reference.settings import settings_for

    probes = np.zeros((1, 3))

    def keys(st, study="full"):
        out = []
        for j in planned_solves(st, study):
            out.append(reference_key(j.spec, j.angle_deg, push_depths(j.step), Material(), probes,
                                     "frictionless", j.penalty_scale))
        return out

    full, quick = settings_for(False), settings_for(True)
    assert len(set(keys(full))) == 16 and len(set(keys(quick))) == 5
    assert len(set(keys(full, "mirror"))) == 8 and set(keys(full, "mirror")) <= set(keys(full))
    hold = planned_solves(full, "holdout")
    assert len(set(keys(full, "holdout"))) == 4 and set(keys(full, "holdout")) <= set(keys(full))
    assert sorted(j.angle_deg for j in hold) == [0.0, 0.0, 5.0, 10.0]
    # the table's pushes and the held-out ones are read as their stable branch (stable_path), the levels not
    assert sorted((j.angle_deg, j.stable, j.spec == full.snap_spec) for j in hold) == \
        [(0.0, False, False), (0.0, True, True), (5.0, True, True), (10.0, True, True)]
    assert {j.spec for j in planned_solves(full) if j.stable} == \
        {full.snap_spec} | {replace(full.levels[-2], skin_h=h) for h in full.skin_sizes}
    assert [j.stable for j in planned_solves(quick)].count(True) == 3
    assert holdout_grid(full).grid.angles_deg == (0.0, 10.0)
    with pytest.raises(ValueError, match="held-out azimuth 25 deg is outside"):
        holdout_grid(replace(full, holdout_deg=(25.0,)))
    assert holdout_grid(replace(full, holdout_deg=(15.0,))).grid.angles_deg == (0.0, 10.0, 20.0)
    with pytest.raises(ValueError, match="hold no azimuth out"):
        holdout_grid(quick)
    # the fold study: the last three levels (the full run's), the tip-refined sequence and its tip check
    assert len(set(keys(full, "fold"))) == 7 and len(set(keys(full, "fold")) & set(keys(full))) == 3
    assert len(set(keys(quick, "fold"))) == 4 and len(set(keys(quick, "fold")) & set(keys(quick))) == 2
    # the material study (per material): the five levels, and the snapshot mesh's stable branch (its table)
    mat = planned_solves(full, "material")
    assert len(set(keys(full, "material"))) == 6 and len(set(keys(full, "material")) & set(keys(full))) == 5
    assert [j.spec for j in mat if j.stable] == [full.snap_spec] == [full.levels[-2]]
    # its tip check is the fold study's (3.4 mm tube + 0.8 mm tip): one solve, shared
    assert set(keys(full, "material")) - set(keys(full)) <= set(keys(full, "fold"))
    assert len(set(keys(quick, "material"))) == 2                       # quick: no tip check
    with pytest.raises(ValueError, match="study must be"):
        planned_solves(full, "mirror_only")
    costs = [j.cost() for j in planned_solves(full)]
    assert costs == sorted(costs, reverse=True)


def _fake_path_dict(n_dof: int, depths) -> dict:
    d = len(depths)
    return {"u_dof": np.zeros((d, n_dof, 3), np.float32), "force": np.arange(d, dtype=float),
            "newton": np.ones(d, int), "converged": np.ones(d, bool), "min_detF": np.ones(d),
            "inverted": np.zeros(d, int), "max_strain": np.zeros(d), "penetration": np.zeros(d)}


class _KeyRecorder:
    """A stand-in cache for :func:`reference_path` that records (key, what) of every lookup and has nothing."""

    def __init__(self):
        self.seen = []

    def load(self, kind, key):
        return None

    def path(self, kind, key):
        return None

    def get_or_compute(self, kind, key, compute, what):
        self.seen.append((key, what))
        return {}, True, 0.0


def test_reference_path_solves_off_axis_pushes_on_the_half_model_under_one_key():
    """Away from azimuth 0 a quarter-model spec (``half_z``) is solved on its half model, as the snapshot table
    meshes it: the quarter and the half spec give one cache entry (one solve), and −0° is 0°."""
    from dataclasses import replace

    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.paths import push_depths, reference_path
    from flexsheet.fem.snapshots import DEFAULT_REF_SPEC

    c = _KeyRecorder()
    probes = np.zeros((2, 3))
    d = push_depths(0.0025)
    for spec, a in ((DEFAULT_REF_SPEC, 10.0), (replace(DEFAULT_REF_SPEC, half_z=False), 10.0),
                    (DEFAULT_REF_SPEC, 0.0), (DEFAULT_REF_SPEC, -0.0)):
        reference_path(spec, a, d, Material(), c, probes)
    (k10q, w10), (k10h, _), (k0, w0), (k0m, _) = c.seen
    assert k10q == k10h and "hz=0" in w10 and k0 == k0m and "hz=1" in w0 and k0 != k10q


def test_node_table_command_builds_the_table_the_node_looks_up(tmp_path, monkeypatch):
    """`--node-table` builds DEFAULT_GRID on DEFAULT_REF_SPEC with the node's default finger and material, and
    stores it under the key the FEM node loads; each azimuth's states come from a cached stable path on the
    table's mesh (its loading path: reference_path takes the half model away from azimuth 0), and `--azimuth A`
    solves just that path (the solves themselves are hours: replaced by markers)."""
    from flexsheet.experiments.fem import cli as CLI
    from flexsheet.experiments.fem import runs as RUNS
    from flexsheet.experiments.fem.cli import main
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference import node_table as NT
    from flexsheet.fem.reference import paths as R
    from flexsheet.fem.reference.settings import settings_for
    from flexsheet.fem.reference.snapshot_build import load_or_build
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC
    from flexsheet.model.scene_parts import GENT_JM_RUBBER
    from nodes.fem.node import FemParams

    paths, seen = [], {}
    # the repository's shipped table has this very key: keep it out, the build below must run
    monkeypatch.setattr("flexsheet.fem.cache.SHIPPED_DIR", str(tmp_path / "no_shipped"))

    def fake_path(spec, angle_deg, depths, mat, cache, probes, contact="frictionless", penalty_scale=None):
        paths.append((spec, angle_deg, round(float(depths[-1]), 9), len(depths)))
        return _fake_path_dict(4, depths)

    def fake_build(grid, spec, material, finger_radius, solved=None, **kw):
        seen["build"] = (grid, spec, material.nu, finger_radius)
        seen["states"] = {a: solved(a, None, grid.depths()[1:]) for a in (0.0, 30.0)}
        return {"marker": np.arange(3.0), "seconds": np.array([1.0])}

    monkeypatch.setattr(R, "reference_path", fake_path)
    # stable_path's unloading sweep (test_stable_path_takes_the_unloaded_rows_only...) left out: its loading read
    monkeypatch.setattr(NT, "stable_path", lambda *a, **kw: R.reference_path(*a, **kw))
    monkeypatch.setattr("flexsheet.fem.reference.snapshot_build.build_table", fake_build)
    # the rendered vertices the paths are sampled at (the full settings' linear model: a 17 s precompute)
    verts = np.random.default_rng(0).uniform(-0.03, 0.03, (7, 3)).astype(np.float32)
    for where in (NT, RUNS):            # the node table's build and the --level run
        monkeypatch.setattr(where, "realtime_model",
                            lambda st, mat, cache_dir: SimpleNamespace(rest_vertices=verts))
    # the report reads a real table's fields (tests/unit/fem/test_fem_hyperelastic.py checks the shipped one): a marker here
    reported = {}
    monkeypatch.setattr(NT, "node_table_report", lambda table, paths, mat, key: reported.update(
        angles=sorted(paths), Jm=mat.Jm, key=key) or {"key": key})
    monkeypatch.setattr(CLI, "plot_node_table", lambda out, rep: None)
    monkeypatch.setattr(NT, "table_update_ms", lambda table, verts, mat: {"median_ms": -1.0})
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--jobs", "1"]) == 0
    assert reported["angles"] == list(DEFAULT_GRID.angles_deg) and reported["Jm"] == GENT_JM_RUBBER
    with open(tmp_path / "o" / "node_table.json") as fh:
        assert json.load(fh) == {"key": reported["key"], "update": {"median_ms": -1.0}, "held_out": [],
                                 "between_depths": []}
    p = FemParams()
    assert seen["build"] == (DEFAULT_GRID, DEFAULT_REF_SPEC, p.nu, p.finger_radius)
    assert paths == [(DEFAULT_REF_SPEC, 0.0, 0.05, 20), (DEFAULT_REF_SPEC, 30.0, 0.05, 20)]   # fake_build's reads
    st30 = seen["states"][30.0]
    assert [s.depth for s in st30] == pytest.approx(DEFAULT_GRID.depths()[1:]) and st30[-1].force == 19.0
    paths.clear()
    seen.clear()
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table"]) == 0
    assert paths == [] and seen == {}           # the table is found: nothing solved or built again
    paths.clear()
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table",
                   "--azimuth", "20"]) == 0
    assert paths == [(DEFAULT_REF_SPEC, 20.0, 0.05, 20)]
    # azimuth 0 of the node table is the full run's 3.4 mm convergence level: the same solve (cache key)
    calls = []
    for where in (R, RUNS):             # the node table's stable_path reads R's, the --level run its own
        monkeypatch.setattr(where, "reference_path", lambda spec, a, d, mat, cache, probes, contact="frictionless",
                            *r: calls.append((spec, a, np.round(d, 9).tolist(), probes.tobytes(), contact)) or {})
    level = [lv.h_fine for lv in settings_for(False).levels].index(DEFAULT_REF_SPEC.h_fine)
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--level", str(level)]) == 0
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table",
                   "--azimuth", "-0"]) == 0
    assert len(calls) == 2 and calls[0] == calls[1] and calls[0][3] == verts.astype(float).tobytes()
    with pytest.raises(SystemExit, match="--azimuth must be one of"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--azimuth", "15"])
    with pytest.raises(SystemExit, match="--azimuth is for --node-table"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--azimuth", "10"])
    with pytest.raises(SystemExit, match="node-table"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--quick"])
    # the default material is the default scene's (Gent, Jm 97.2): the key the bare FEM node looks up too
    table, hit, _ = load_or_build(ArrayCache(str(tmp_path / "c")), DEFAULT_GRID, DEFAULT_REF_SPEC,
                                  Material(p.E, p.nu, GENT_JM_RUBBER), p.finger_radius, build=False)
    assert hit and np.array_equal(table["marker"], np.arange(3.0))


def test_stable_path_takes_the_unloaded_rows_only_and_keeps_the_dtypes(tmp_path, monkeypatch):
    """stable_path: rows where stable_states took the unloaded state come from its record, the others are the
    loading path's as cached, every array keeps its dtype; the energies and branch flags are stored; a second
    call reads the "stable" cache entry without touching the loading path."""
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference import paths as X
    from flexsheet.fem.reference.mesh import RefSpec

    depths = np.array([0.01, 0.02, 0.03])
    n_dof, k = 4, 2
    base = {**_fake_path_dict(n_dof, depths), "u": np.zeros((3, k, 3)), "inverted_qp": np.zeros(3, int),
            "inverted_nodal_visible": np.zeros(3, int), "seconds": np.array(1.0), "cpu_seconds": np.array(1.0)}
    calls = []

    def fake_reference_path(*a, **kw):
        calls.append(a[1])
        return base

    class FakeModel:
        mesh = type("M", (), {"radius": 0.035, "center": np.zeros(3)})()

    def fake_stable_states(model, caps, states, step, iters, log):
        moved = [replace(s, u=s.u + 1.0, force=10.0 + j) for j, s in enumerate(states)]
        return ([states[0], moved[1], states[2]], np.array([0, 1, 0]),
                np.array([[3.0, 3.0], [2.0, 1.5], [1.0, 1.0]]))

    def fake_record(model, states, probes, angle_deg):
        n = len(states)
        return {"u": np.full((n, k, 3), 7.0), "u_dof": np.stack([s.u for s in states]).astype(np.float64),
                "force": np.array([s.force for s in states]), "inverted": np.full(n, 5),
                "inverted_qp": np.full(n, 6), "inverted_nodal_visible": np.full(n, 2), "min_detF": np.full(n, 0.5),
                "max_strain": np.full(n, 0.25), "penetration": np.full(n, 1e-5), "newton": np.full(n, 9),
                "converged": np.array([True] * n)}

    monkeypatch.setattr(X, "reference_path", fake_reference_path)
    monkeypatch.setattr(X, "reference_model", lambda *a, **kw: FakeModel())
    monkeypatch.setattr(X, "stable_states", fake_stable_states)
    monkeypatch.setattr(X, "_path_record", fake_record)
    cache = ArrayCache(str(tmp_path), None, shipped_dir=None)
    spec, probes = RefSpec(0.016, 0.012), np.zeros((k, 3))
    z = X.stable_path(spec, 10.0, depths, Material(), cache, probes)
    assert z["branch"].tolist() == [0, 1, 0] and z["energy_unloading"].tolist() == [3.0, 1.5, 1.0]
    assert z["force"].tolist() == [0.0, 11.0, 2.0]                  # the loading path's 0 and 2, the record's 11
    assert z["u"][1].max() == 7.0 and z["u"][[0, 2]].max() == 0.0
    assert z["u_dof"].dtype == np.float32 and np.all(z["u_dof"][1] == 1.0) and np.all(z["u_dof"][0] == 0.0)
    assert z["newton"].tolist() == [1, 9, 1] and z["inverted_qp"].tolist() == [0, 6, 0]
    assert z["converged"].dtype == bool
    assert calls == [10.0]
    z2 = X.stable_path(spec, 10.0, depths, Material(), cache, probes)   # the cached entry, no loading path read
    assert calls == [10.0] and z2["force"].tolist() == [0.0, 11.0, 2.0]


def test_node_table_report_and_holdout_on_an_analytic_table(tmp_path, monkeypatch):
    """node_table.json's parts on a table whose field is known in closed form (the rigid rotation of one field
    with the finger, test_fem_hyperelastic._analytic_table): the apex check reads the surface point under the
    fingertip (the field moves it d outward there, so −2d against the push), the held-out azimuth is answered
    by the table's rotate-and-blend (< 5 µm) and a 1 mm flaw in the held-out solve at a visible vertex
    reads 1 mm; the update timing and the chart are written; bad held-out azimuths are refused. (The table's 1° θ
    grid interpolates display-frame components of a rotating field: a few µm, not exact.)"""
    from test_fem_hyperelastic import C, L, R, _analytic_table

    from flexsheet.experiments.fem.cli import main
    from flexsheet.experiments.fem.plots import plot_node_table
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference import node_table as NT
    from flexsheet.fem.reference.node_table import (
        node_table_between_depths,
        node_table_compare,
        node_table_holdout,
        node_table_report,
        table_update_ms,
        twin_spec,
    )
    from flexsheet.fem.snapshots import DEFAULT_REF_SPEC
    from flexsheet.model.scene_parts import GENT_JM_RUBBER

    depths = [0.0, 0.01, 0.02]
    tab = _analytic_table([0.0, 10.0], depths)
    mat = Material(1e4, 0.45, GENT_JM_RUBBER)

    def path(extra=0):
        return {"dofs": np.array(100 + extra), "cpu_seconds": np.array(1.0), "newton": np.array([3, 4]),
                "converged": np.array([True, True]), "branch": np.array([0, 1]), "unload_seconds": np.array(2.0)}

    rep = node_table_report(tab, {0.0: path(), 10.0: path(1)}, mat, "k")
    assert [r["azimuth_deg"] for r in rep["azimuths"]] == [0.0, 10.0] and rep["material"]["Jm"] == GENT_JM_RUBBER
    for r in rep["azimuths"]:
        assert r["apex_depth_error_mm"] == pytest.approx([-20.0, -40.0], abs=1e-3)
        assert r["unloaded_state_at_mm"] == [20.0] and r["force_N"] == pytest.approx([0.0, 1.0, 2.0])
    assert [r["dofs"] for r in rep["azimuths"]] == [100, 101]
    # a path this machine's cache lacks (the table shipped, its solves not): its facts are left out, not invented
    r10 = node_table_report(tab, {0.0: path(), 10.0: None}, mat, "k")["azimuths"][1]
    assert r10["path"] == "not in this machine's cache" and "dofs" not in r10 and r10["force_N"][2] == 2.0
    # held out at 5 deg: the rendered vertices on the side, away from the held back half and the fingertip
    th, ys = np.meshgrid(np.radians(np.arange(-60.0, 61.0, 7.5)), np.array([-0.04, -0.02, 0.0, 0.02, 0.04]))
    th, ys = th.ravel(), ys.ravel()
    verts = np.column_stack([C[0] + R * np.cos(th), ys, C[2] + R * np.sin(th)])
    mesh = SimpleNamespace(radius=R, center=C, fixed=np.zeros(len(verts), bool))
    rm = SimpleNamespace(rest_vertices=verts.astype(np.float32), mesh=mesh, surface_nodes=np.arange(len(verts)),
                         snapshots=None)
    phi = math.radians(5.0)

    def exact(d):                       # the analytic field of a push at 5 deg (the table's own formula)
        rel = th - phi
        fr, ft = d * (1.0 + 0.3 * rel) * (1.0 - np.abs(ys) / L), d * 0.2 * rel
        return np.column_stack([fr * np.cos(th) - ft * np.sin(th), d * 0.1 * ys / L, fr * np.sin(th) + ft * np.cos(th)])

    held = {"u": np.stack([exact(d) for d in depths[1:]]), "dofs": np.array(7), "cpu_seconds": np.array(3.0)}
    monkeypatch.setattr(NT, "stable_path", lambda *a, **kw: held)
    h = node_table_holdout(tab, mat, None, rm, 5.0)
    assert h["depths_mm"] == pytest.approx([10.0, 20.0]) and h["max_error_mm"] < 5e-3    # 1° grid: µm
    far = int(np.argmax(np.abs(th - phi)))                 # a vertex far from the fingertip: visible
    held["u"] = held["u"].copy()
    held["u"][1, far] += [0.0, 0.001, 0.0]
    h = node_table_holdout(tab, mat, None, rm, 5.0)
    assert h["error_mm"][1] == pytest.approx(1.0, abs=1e-3) and h["over_target_from_mm"] == pytest.approx(20.0)
    # the twin (--mesh-check): the same push on the table mesh's twin (here 0.5 mm off at 10 mm, the same at 20 mm),
    # its difference read as the mesh's noise
    twin_u = held["u"].copy()
    twin_u[0, far] += [0.0, 0.0, 0.0005]
    specs = []
    monkeypatch.setattr(NT, "stable_path", lambda spec, *a, **kw: specs.append(spec) or (
        held if spec == DEFAULT_REF_SPEC else {**held, "u": twin_u, "converged": np.array([True, True])}))
    h = node_table_holdout(tab, mat, None, rm, 5.0, twin=True)
    assert specs == [DEFAULT_REF_SPEC, twin_spec(DEFAULT_REF_SPEC)]
    assert specs[1].refine_radius == pytest.approx(DEFAULT_REF_SPEC.refine_radius + 1e-4)
    assert h["twin"]["noise_mm"] == pytest.approx([0.5, 0.0], abs=1e-6) and h["error_mm"][1] == pytest.approx(1.0, abs=1e-3)
    # two tables judged side by side at the same pushes: the held-out one's error as node_table_holdout gives it,
    # and a table azimuth named as held, not judged
    rows = node_table_compare({"a": tab, "b": tab}, [5.0, 10.0], mat, None, rm)
    assert [r["azimuth_deg"] for r in rows] == [5.0, 10.0] and rows[0]["depths_mm"] == pytest.approx([10.0, 20.0])
    assert rows[0]["a"] == rows[0]["b"] and rows[0]["a"]["error_mm"][1] == pytest.approx(1.0, abs=1e-3)
    assert rows[0]["a"]["over_target_from_mm"] == pytest.approx(20.0) and rows[1] == {
        "azimuth_deg": 10.0, "a": "holds this azimuth", "b": "holds this azimuth"}
    for bad in (0.0, 10.0, 12.0, -3.0):
        with pytest.raises(ValueError, match="held-out azimuth"):
            node_table_holdout(tab, mat, None, rm, bad)
    # between the table's depths at one of its azimuths: the analytic field is linear in depth, so the table's
    # depth blend is exact at the midpoints too; a 1 mm flaw at a midpoint reads there, and only there
    fine = [0.005, 0.01, 0.015, 0.02]

    def exact0(d):
        fr, ft = d * (1.0 + 0.3 * th) * (1.0 - np.abs(ys) / L), d * 0.2 * th
        return np.column_stack([fr * np.cos(th) - ft * np.sin(th), d * 0.1 * ys / L, fr * np.sin(th) + ft * np.cos(th)])

    seen = []
    on0 = {"u": np.stack([exact0(d) for d in fine]), "dofs": np.array(9), "cpu_seconds": np.array(4.0),
           "branch": np.array([0, 0, 1, 1])}
    monkeypatch.setattr(NT, "stable_path", lambda spec, a, d, *r, **kw: seen.append(np.round(d, 9).tolist()) or on0)
    b = node_table_between_depths(tab, mat, None, rm, 0.0)
    assert seen == [fine] and b["depths_mm"] == pytest.approx([5.0, 10.0, 15.0, 20.0]) and b["max_error_mm"] < 5e-3
    assert b["unloaded_state_at_mm"] == pytest.approx([15.0, 20.0]) and b["over_target_from_mm"] is None
    far0 = int(np.argmax(np.abs(th)))
    on0["u"] = on0["u"].copy()
    on0["u"][2, far0] += [0.0, 0.0, 0.001]
    b = node_table_between_depths(tab, mat, None, rm, 0.0)
    assert b["max_error_mm_between_depths"] == pytest.approx(1.0, abs=1e-3) and b["max_error_mm_at_table_depths"] < 5e-3
    assert b["over_target_from_mm"] == pytest.approx(15.0)
    with pytest.raises(ValueError, match="one of the table's"):
        node_table_between_depths(tab, mat, None, rm, 5.0)
    rep["between_depths"] = [b]
    rep["update"] = table_update_ms(tab, verts, mat, n=3)
    assert rep["update"]["calls"] == 9 and 0.0 < rep["update"]["median_ms"] <= rep["update"]["p90_ms"]
    rep["held_out"] = [h]
    plot_node_table(str(tmp_path), rep)
    assert os.path.getsize(tmp_path / "node_table.png") > 5000
    for args, word in ((["--node-table", "--holdout-azimuth", "10"], "strictly between"),
                       (["--node-table", "--holdout-azimuth", "5"], "strictly between"),      # a table azimuth
                       (["--node-table", "--holdout-azimuth", "75"], "strictly between"),
                       (["--holdout-azimuth", "8.75"], "is for --node-table"),
                       (["--node-table", "--ship", "--azimuth", "10"], "--ship is for"),
                       (["--ship"], "--ship is for"),
                       (["--node-table", "--ship", "--contact", "sticking"], "frictionless"),
                       (["--node-table", "--between-depths", "8.75"], "one of the node table's"),
                       (["--between-depths", "0"], "is for --node-table"),
                       (["--node-table", "--mesh-check"], "--mesh-check is for")):
        with pytest.raises(SystemExit, match=word):
            main(["--out", str(tmp_path / "o"), "--cache-dir", ""] + args)


def test_scheduler_address_is_checked_before_any_work(tmp_path):
    """--scheduler takes a dask scheduler's tcp://HOST:PORT; anything else is refused naming the value, and
    the local cluster stays the default."""
    from flexsheet.fem.reference import workers

    with pytest.raises(ValueError, match="tcp://HOST:PORT, got 'localhost:8786'"):
        workers.set_scheduler("localhost:8786")
    with pytest.raises(ValueError, match="got 'tcp://h:99999'"):
        workers.set_scheduler("tcp://h:99999")
    assert workers.SCHEDULER is None and not workers.parallel(1) and workers.parallel(2)
    try:
        workers.set_scheduler("tcp://10.77.0.1:8786")
        assert workers.parallel(1)
    finally:
        workers.set_scheduler(None)
    from flexsheet.experiments.fem.cli import main

    with pytest.raises(SystemExit, match="--scheduler must be tcp://HOST:PORT"):
        main(["--quick", "--scheduler", "nowhere", "--out", str(tmp_path)])
