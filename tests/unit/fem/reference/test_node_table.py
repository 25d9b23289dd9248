"""The FEM node's shipped snapshot table (flexsheet/fem/reference/node_table.py): `--node-table` builds the
table the node looks up, and node_table.json's parts (report, held-out azimuths, between depths, update time)
on an analytic table."""

import json
import math
import os
from types import SimpleNamespace

import numpy as np
import pytest

# the slow tier, with the FEM experiment's quick run
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]


def _fake_path_dict(n_dof: int, depths) -> dict:
    d = len(depths)
    return {"u_dof": np.zeros((d, n_dof, 3), np.float32), "force": np.arange(d, dtype=float),
            "newton": np.ones(d, int), "converged": np.ones(d, bool), "min_detF": np.ones(d),
            "inverted": np.zeros(d, int), "max_strain": np.zeros(d), "penetration": np.zeros(d)}


def test_node_table_command_builds_the_table_the_node_looks_up(tmp_path, monkeypatch):
    """`--node-table` builds DEFAULT_GRID on DEFAULT_REF_SPEC with the node's default finger and material, and
    stores it under the key the FEM node loads; each azimuth's states come from a cached stable path on the
    table's mesh (its loading path: reference_path takes the half model away from azimuth 0), and
    `--azimuth A` solves just that path (the solves themselves are hours: replaced by markers)."""
    from flexsheet.experiments.fem import cli as CLI
    from flexsheet.experiments.fem import runs as RUNS
    from flexsheet.experiments.fem.cli import main
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference import node_table as NT
    from flexsheet.fem.reference import paths as R
    from flexsheet.fem.reference.snapshot_build import load_or_build
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC
    from flexsheet.model.scene_parts import GENT_JM_RUBBER
    from flexsheet.model.scenes import DEFAULT_SCENE_FILE, load_scene

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
    # stable_path's unloading sweep
    # (test_stable_path_takes_the_unloaded_rows_only...) left out: its loading read
    monkeypatch.setattr(NT, "stable_path", lambda *a, **kw: R.reference_path(*a, **kw))
    monkeypatch.setattr("flexsheet.fem.reference.snapshot_build.build_table", fake_build)
    # the rendered vertices the paths are sampled at (the full settings' linear model: a 17 s precompute)
    verts = np.random.default_rng(0).uniform(-0.03, 0.03, (7, 3)).astype(np.float32)
    for where in (NT, RUNS):            # the node table's build and the --level run
        monkeypatch.setattr(where, "realtime_model",
                            lambda st, mat, cache_dir: SimpleNamespace(rest_vertices=verts))
    # the report reads a real table's fields (tests/unit/fem/test_snapshots.py
    # checks the shipped one): a marker here
    reported = {}
    monkeypatch.setattr(NT, "node_table_report", lambda table, paths, mat, key: reported.update(
        angles=sorted(paths), Jm=mat.Jm, key=key) or {"key": key})
    monkeypatch.setattr(CLI, "plot_node_table", lambda out, rep: None)
    monkeypatch.setattr(NT, "table_update_ms", lambda table, verts, mat: {"median_ms": -1.0})
    assert (
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--jobs",
              "1"]) == 0)
    assert reported["angles"] == list(DEFAULT_GRID.angles_deg) and reported["Jm"] == GENT_JM_RUBBER
    with open(tmp_path / "o" / "node_table.json") as fh:
        assert json.load(fh) == {"key": reported["key"], "update": {"median_ms": -1.0}, "held_out": [],
                                 "between_depths": []}
    sc = load_scene(DEFAULT_SCENE_FILE)           # the node's default scene: its ν and finger
    assert seen["build"] == (DEFAULT_GRID, DEFAULT_REF_SPEC, sc.material.nu, sc.finger.radius)
    # fake_build's reads
    assert paths == [(DEFAULT_REF_SPEC, 0.0, 0.05, 20), (DEFAULT_REF_SPEC, 30.0, 0.05, 20)]
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
    # azimuth 0 of the node table: its own mesh (4.5 mm, the rim on a mesh line) under the default scene's law
    calls = []
    monkeypatch.setattr(R, "reference_path", lambda spec, a, d, mat, cache, probes, contact="frictionless",
                        *r: calls.append((spec, a, np.round(d, 9).tolist(), probes.tobytes(), contact)) or {})
    assert main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table",
                   "--azimuth", "-0"]) == 0
    assert len(calls) == 1 and calls[0][0] == DEFAULT_REF_SPEC and calls[0][4] == "sticking"
    assert calls[0][3] == verts.astype(float).tobytes()
    with pytest.raises(SystemExit, match="--azimuth must be one of"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--azimuth",
              "15"])
    with pytest.raises(SystemExit, match="--azimuth is for --node-table"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--azimuth", "10"])
    with pytest.raises(SystemExit, match="node-table"):
        main(["--out", str(tmp_path / "o"), "--cache-dir", str(tmp_path / "c"), "--node-table", "--quick"])
    # the default material and law are the default scene's (Gent, Jm 97.2;
    # sticking): the key the node looks up without a scene: param too
    table, hit, _ = load_or_build(ArrayCache(str(tmp_path / "c")), DEFAULT_GRID, DEFAULT_REF_SPEC,
                                  Material(sc.material.E, sc.material.nu, GENT_JM_RUBBER), sc.finger.radius,
                                  build=False,
                                  contact="sticking")
    assert hit and np.array_equal(table["marker"], np.arange(3.0))


def test_node_table_report_and_holdout_on_an_analytic_table(tmp_path, monkeypatch):
    """node_table.json's parts on a table whose field is known in closed form (the rigid rotation of one field
    with the finger, test_snapshots._analytic_table): the apex check reads the surface point under the
    fingertip (the field moves it d outward there, so −2d against the push), the held-out azimuth is answered
    by the table's rotate-and-blend (< 5 µm) and a 1 mm flaw in the held-out solve at a visible vertex reads 1
    mm; the update timing and the chart are written; bad held-out azimuths are refused. (The table's 1° θ grid
    interpolates display-frame components of a rotating field: a few µm, not exact.)"""
    from test_snapshots import C, L, R, _analytic_table

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
                "converged": np.array([True, True]), "branch": np.array([0, 1]),
                "unload_seconds": np.array(2.0)}

    rep = node_table_report(tab, {0.0: path(), 10.0: path(1)}, mat, "k")
    assert ([r["azimuth_deg"] for r in rep["azimuths"]] == [0.0, 10.0]
            and rep["material"]["Jm"] == GENT_JM_RUBBER)
    for r in rep["azimuths"]:
        assert r["apex_depth_error_mm"] == pytest.approx([-20.0, -40.0], abs=1e-3)
        assert r["unloaded_state_at_mm"] == [20.0] and r["force_N"] == pytest.approx([0.0, 1.0, 2.0])
    assert [r["dofs"] for r in rep["azimuths"]] == [100, 101]
    # a path this machine's cache lacks (the table shipped,
    # its solves not): its facts are left out, not invented
    r10 = node_table_report(tab, {0.0: path(), 10.0: None}, mat, "k")["azimuths"][1]
    assert r10["path"] == "not in this machine's cache" and "dofs" not in r10 and r10["force_N"][2] == 2.0
    # held out at 5 deg: the rendered vertices on the side, away from the held back half and the fingertip
    th, ys = np.meshgrid(np.radians(np.arange(-60.0, 61.0, 7.5)), np.array([-0.04, -0.02, 0.0, 0.02, 0.04]))
    th, ys = th.ravel(), ys.ravel()
    verts = np.column_stack([C[0] + R * np.cos(th), ys, C[2] + R * np.sin(th)])
    mesh = SimpleNamespace(radius=R, center=C, fixed=np.zeros(len(verts), bool))
    nt, ny = 17, 5                       # the patch's triangles (θ fastest), as the renderer draws them
    faces = np.array([f for iy in range(ny - 1) for it in range(nt - 1) for f in (
        [iy * nt + it, iy * nt + it + 1, (iy + 1) * nt + it],
        [iy * nt + it + 1, (iy + 1) * nt + it + 1, (iy + 1) * nt + it])])
    rm = SimpleNamespace(rest_vertices=verts.astype(np.float32), mesh=mesh,
                         surface_nodes=np.arange(len(verts)),
                         snapshots=None, faces=faces)

    def radial(i, mm):                   # a flaw of mm along the surface normal at vertex i
        return mm * 1e-3 * np.array([np.cos(th[i]), 0.0, np.sin(th[i])])
    phi = math.radians(5.0)

    def exact(d):                       # the analytic field of a push at 5 deg (the table's own formula)
        rel = th - phi
        fr, ft = d * (1.0 + 0.3 * rel) * (1.0 - np.abs(ys) / L), d * 0.2 * rel
        return np.column_stack([fr * np.cos(th) - ft * np.sin(th), d * 0.1 * ys / L,
                                fr * np.sin(th) + ft * np.cos(th)])

    held = {"u": np.stack([exact(d) for d in depths[1:]]), "dofs": np.array(7), "cpu_seconds": np.array(3.0)}
    monkeypatch.setattr(NT, "stable_path", lambda *a, **kw: held)
    h = node_table_holdout(tab, mat, None, rm, 5.0)
    assert h["depths_mm"] == pytest.approx([10.0, 20.0]) and h["max_shape_px"] < 0.01    # 1° grid: µm
    # far from the finger
    far = int(np.flatnonzero((np.abs(th + math.radians(60.0)) < 1e-9) & (ys == 0.0))[0])
    held["u"] = held["u"].copy()
    held["u"][1, far] += radial(far, 2.0)
    h = node_table_holdout(tab, mat, None, rm, 5.0)
    # 2 mm across the surface at -60°: ~1.7 mm on the screen,
    # less what the bump's slope takes from the distance
    assert h["shape_px"][0] < 0.01 and 1.2 < h["shape_px"][1] < 3.0 and h[
        "over_target_from_mm"] == pytest.approx(20.0)
    # the twin (--mesh-check): the same push on the table mesh's twin (here 0.5 mm
    # off at 10 mm, the same at 20 mm), its difference read as the mesh's noise
    twin_u = held["u"].copy()
    twin_u[0, far] += radial(far, 0.5)
    specs = []
    monkeypatch.setattr(NT, "stable_path", lambda spec, *a, **kw: specs.append(spec) or (
        held if spec == DEFAULT_REF_SPEC else {**held, "u": twin_u, "converged": np.array([True, True])}))
    h = node_table_holdout(tab, mat, None, rm, 5.0, twin=True)
    assert specs == [DEFAULT_REF_SPEC, twin_spec(DEFAULT_REF_SPEC)]
    assert specs[1].refine_radius == pytest.approx(DEFAULT_REF_SPEC.refine_radius + 1e-4)
    assert 0.2 < h["twin"]["noise_px"][0] < 0.8 and h["twin"]["noise_px"][1] < 1e-6
    assert 1.2 < h["shape_px"][1] < 3.0
    # two tables judged side by side at the same pushes: the held-out one's error
    # as node_table_holdout gives it, and a table azimuth named as held, not judged
    rows = node_table_compare({"a": tab, "b": tab}, [5.0, 10.0], mat, None, rm)
    assert ([r["azimuth_deg"] for r in rows] == [5.0, 10.0]
            and rows[0]["depths_mm"] == pytest.approx([10.0, 20.0]))
    assert rows[0]["a"] == rows[0]["b"] and rows[0]["a"]["shape_px"][1] == pytest.approx(h["shape_px"][1],
                                                                                         abs=1e-3)
    assert rows[0]["a"]["over_target_from_mm"] == pytest.approx(20.0) and rows[1] == {
        "azimuth_deg": 10.0, "a": "holds this azimuth", "b": "holds this azimuth"}
    for bad in (0.0, 10.0, 12.0, -3.0):
        with pytest.raises(ValueError, match="held-out azimuth"):
            node_table_holdout(tab, mat, None, rm, bad)
    # between the table's depths at one of its azimuths: the analytic field is linear in depth, so the table's
    # depth blend is exact at the midpoints too; a 2 mm flaw at a midpoint reads there, and only there
    fine = [0.005, 0.01, 0.015, 0.02]

    def exact0(d):
        fr, ft = d * (1.0 + 0.3 * th) * (1.0 - np.abs(ys) / L), d * 0.2 * th
        return np.column_stack([fr * np.cos(th) - ft * np.sin(th), d * 0.1 * ys / L,
                                fr * np.sin(th) + ft * np.cos(th)])

    seen = []
    on0 = {"u": np.stack([exact0(d) for d in fine]), "dofs": np.array(9), "cpu_seconds": np.array(4.0),
           "branch": np.array([0, 0, 1, 1])}
    monkeypatch.setattr(NT, "stable_path", lambda spec, a, d, *r,
                        **kw: seen.append(np.round(d, 9).tolist()) or on0)
    b = node_table_between_depths(tab, mat, None, rm, 0.0)
    assert seen == [fine] and b["depths_mm"] == pytest.approx([5.0, 10.0, 15.0,
                                                               20.0]) and b["max_shape_px"] < 0.01
    assert b["unloaded_state_at_mm"] == pytest.approx([15.0, 20.0]) and b["over_target_from_mm"] is None
    on0["u"] = on0["u"].copy()
    on0["u"][2, far] += radial(far, 2.0)
    b = node_table_between_depths(tab, mat, None, rm, 0.0)
    assert 1.2 < b["max_shape_px_between_depths"] < 3.0 and b["max_shape_px_at_table_depths"] < 0.01
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
                       (["--node-table", "--holdout-azimuth", "20"], "strictly between"),  # a table azimuth
                       (["--node-table", "--holdout-azimuth", "75"], "strictly between"),
                       (["--holdout-azimuth", "8.75"], "is for --node-table"),
                       (["--node-table", "--ship", "--azimuth", "10"], "--ship is for"),
                       (["--ship"], "--ship is for"),
                       (["--node-table", "--ship", "--contact", "frictionless"], "sticking"),
                       (["--node-table", "--between-depths", "8.75"], "one of the node table's"),
                       (["--between-depths", "0"], "is for --node-table"),
                       (["--node-table", "--mesh-check"], "--mesh-check is for")):
        with pytest.raises(SystemExit, match=word):
            main(["--out", str(tmp_path / "o"), "--cache-dir", ""] + args)
