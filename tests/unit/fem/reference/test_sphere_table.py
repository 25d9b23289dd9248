"""The sphere scene's table command (flexsheet/fem/reference/sphere_table.py), its solves replaced by the
closed-form dent of tests/unit/fem/test_sphere_snapshots.py."""

import math
import os

import numpy as np
import pytest
from test_sphere_snapshots import SPHERE, _dent

from flexsheet.fem.sphere_snapshots import SphereGrid, grid_points, sphere_frame
from flexsheet.model.scenes import SCENES_DIR, load_scene


def test_sphere_table_command_reports_held_out_angles_and_ships(tmp_path, monkeypatch):
    """`flexsheet experiment fem --scene sphere.yaml --node-table --holdout-azimuth 5 --ship` with the solves
    replaced by the closed-form dent (they are ~10 min each): the table is assembled under the node's key, the
    held-out angle is answered by the table within the grid's interpolation while the linear model it replaces
    is millimetres off that field, the report and chart are written, the packed table lands in the shipped
    store within float16 rounding; an unconverged push is not shipped; bad arguments are refused."""
    import json

    from flexsheet.experiments.fem.cli import main
    from flexsheet.fem import sphere_snapshots as S
    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.reference import sphere_table as T

    sc = load_scene(SPHERE)
    fr = sphere_frame(sc)
    grid = SphereGrid(depth_max=0.01, depth_step=0.005)
    monkeypatch.setattr(S, "DEFAULT_SPHERE_GRID", grid)
    monkeypatch.setattr(T, "DEFAULT_SPHERE_GRID", grid)       # the table builder reads its own import
    monkeypatch.setattr("flexsheet.fem.cache.SHIPPED_DIR", str(tmp_path / "shipped"))
    pts = grid_points(fr, grid)
    nt, nph = len(grid.thetas()), len(grid.phis())
    calls, converged = [], {"ok": True}

    def fake_alpha_path(sc_, a, grid_, spec, probes, cache):
        calls.append((a, spec))
        n = fr.direction(math.radians(a))
        ds = grid_.depths()
        # a mesh's error: +x, 0.01 x depth x h_fine / 4.5 mm, the opposite sign on a twin
        sign = -1.0 if round(spec[2] * 1e4) % 10 == 1 else 1.0         # a twin's tube is 0.1 mm wider
        off = np.array([sign * 0.01 * spec[1] / 0.0045, 0.0, 0.0])
        return {"field": np.stack([(_dent(pts, fr.center, n, d) + d * off).reshape(nt, nph, 3)
                                   for d in ds]).astype(np.float32),
                "u_probes": np.stack([_dent(probes, fr.center, n, d) + d * off for d in ds]),
                "force": ds ** 1.5 * 100.0, "max_strain": ds, "inverted": np.zeros(len(ds), np.int64),
                "converged": np.array([True] * (len(ds) - 1) + [converged["ok"]]),
                "newton": np.full(len(ds), 5),
                "branch": np.zeros(len(ds), np.int64), "dofs": np.array(123), "cpu_seconds": np.array(1.0),
                "unload_seconds": np.array(2.0)}

    monkeypatch.setattr(T, "alpha_path", fake_alpha_path)
    cache_dir = str(tmp_path / "cache")
    out = tmp_path / "o"
    assert main(["--out", str(out), "--cache-dir", cache_dir, "--scene", str(SPHERE), "--node-table",
                   "--holdout-azimuth", "5", "--ship", "--jobs", "1"]) == 0
    rep = json.loads((out / "sphere_table.json").read_text())
    assert ([r["alpha_deg"] for r in rep["alphas"]] == list(grid.alphas_deg)
            and rep["material"]["law"] == "gent")
    h = rep["held_out"][0]
    assert h["alpha_deg"] == 5.0 and h["depths_mm"] == pytest.approx([5.0, 10.0])
    assert h["max_snapshots_shape_px"] < 0.07 and h["max_linear_shape_px"] > 0.7
    # packed (2° cells, float16) against the full table: the
    # closed-form dent is smooth, so a few µm per mm of depth
    assert 0.0 < rep["shipped"]["packing_error_mm"] < 0.05 and os.path.getsize(out / "sphere_table.png") > 5e3
    key = S.sphere_table_key(sc, grid)
    assert rep["key"] == key and ArrayCache(cache_dir).load("spheresnap", key) is not None
    store = ArrayCache(None, shipped_dir=str(tmp_path / "shipped")).load("spheresnap", key)
    assert store["field"].dtype == np.float16 and store["field"].shape == (7, 3, nt // 2 + 1, nph // 2 + 1, 3)
    assert np.array_equal(store["theta"], grid.thetas()[::2]) and store["theta"][-1] == grid.thetas()[-1]
    converged["ok"] = False                       # a push that did not converge at its deepest step
    with pytest.raises(SystemExit, match="not shipping"):
        main(["--out", str(out), "--cache-dir", str(tmp_path / "cache2"), "--scene", str(SPHERE),
              "--node-table",
                "--ship", "--jobs", "1"])
    # --mesh-check at the held-out angle: every study mesh and its twin
    # solved, each mesh's noise and the table against each read back (at 10
    # mm: 2 x 0.1 mm on the table's h_fine 4.5 mm, 2 x 0.1 x 6/4.5 mm on 6 mm)
    converged["ok"] = True
    calls.clear()
    monkeypatch.setattr(T, "MESH_STUDY_SPECS", ((0.012, 0.006, 0.030, 0.055),))
    assert main(["--out", str(out), "--cache-dir", cache_dir, "--scene", str(SPHERE), "--node-table",
                   "--holdout-azimuth", "5", "--mesh-check", "--jobs", "1"]) == 0
    specs = T.mesh_study_specs(S.DEFAULT_SPHERE_SPEC)
    assert len(specs) == 4 and {c for c in calls if c[0] == 5.0} == {(5.0, x) for x in specs.values()}
    m = json.loads((out / "sphere_table.json").read_text())["mesh_check"][0]
    tab, lv = m["levels"]
    assert m["alpha_deg"] == 5.0 and tab["name"] == "table" and lv["spec_m"][1] == pytest.approx(0.006)
    # in px the 0.2 mm along +x shows as much as the eyes see of it: the figures scale with the offset
    noise = tab["noise_px"][-1]
    assert noise > 0.01 and tab["vs_table_mesh_px"][-1] == 0.0
    assert lv["noise_px"][-1] == pytest.approx(noise * 6 / 4.5, rel=0.03)
    assert lv["vs_table_mesh_px"][-1] == pytest.approx(noise / 2 * (6 / 4.5 - 1), rel=0.03)
    assert abs(lv["snapshots_vs_this_px"][-1] - lv["vs_table_mesh_px"][-1]) < 0.07  # plus the α interpolation
    for args, word in ((["--mesh-check"], "--mesh-check is for"),
                       # the organ has no sphere symmetry: its --node-table is a path table (test_path_table)
                       (["--scene", str(SCENES_DIR / "organ.yaml"), "--node-table", "--azimuth", "10"],
                        "path table takes --stations"),
                       (["--scene", str(SPHERE), "--node-table", "--holdout-azimuth", "60"],
                        "strictly between"),
                       (["--scene", str(SPHERE), "--between-depths", "0"], "cylinder")):
        with pytest.raises(SystemExit, match=word):
            main(["--out", str(out), "--cache-dir", ""] + args)
