"""A scene's first-use path table (flexsheet/fem/first_use_build.py), on the sticky sphere with its short
stroke (tests/unit/conftest.py) and a tiny spec: built in this process it is cached under its key and a second
build solves nothing; built in a worker process it reports each station and hands over the cached table; a
build that fails reports its error and hands over nothing."""

from __future__ import annotations

import threading
import time

import numpy as np
import yaml

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.first_use import FirstUseSpec, first_use_key, load_first_use_table
from flexsheet.fem.first_use_build import FirstUseBuild, build_first_use_table
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.scene_model import SceneModel
from unit.conftest import _scene

#: two stations, one 2.5 mm step, a coarse reference mesh: seconds
TINY = FirstUseSpec(stations=2, h=0.02, h_fine=0.015, refine_radius=0.015, depth_max=0.0025)
MESH = MeshSpec(0.015, 0.006, 0.012)


def _setup(tmp_path):
    sc = _scene()
    path = tmp_path / "sticky_sphere.yaml"
    path.write_text(yaml.safe_dump(sc.model_dump(mode="json")))
    rt = SceneModel(sc, MESH, order=1, cache_dir=str(tmp_path))
    return sc, str(path), rt


def test_a_build_is_cached_under_its_key_and_a_second_one_solves_nothing(tmp_path):
    sc, path, rt = _setup(tmp_path)
    lines = []
    t = time.perf_counter()
    line = build_first_use_table(path, (MESH.h, MESH.h_fine, MESH.refine_radius), 1, str(tmp_path), TINY,
                                 lines.append)
    first_s = time.perf_counter() - t
    assert "2 stations, depth <= 2.5 mm" in line, line
    assert len(lines) == 2 and lines[0].startswith("station 1/2"), lines
    assert "1/1 depths converged" in lines[0], lines
    table = load_first_use_table(rt, ArrayCache(str(tmp_path)), TINY)
    assert table is not None
    assert np.allclose(table["fractions"], [0.0, 1.0]) and np.allclose(table["depths"], [0.0, 0.0025])
    assert table["correction"].shape == (2, 2, len(rt.rest_vertices), 3)
    assert np.all(table["force_ratio"] > 0.2) and np.all(table["force_ratio"] < 5.0)
    assert first_use_key(sc, rt, TINY) != first_use_key(sc, rt, FirstUseSpec(stations=3, depth_max=0.0025))
    rt.attach_path_table(table)                    # a table the real-time model takes
    t = time.perf_counter()
    build_first_use_table(path, (MESH.h, MESH.h_fine, MESH.refine_radius), 1, str(tmp_path), TINY)
    again_s = time.perf_counter() - t
    assert again_s < 0.5 * first_s, (first_s, again_s)       # the stations' pushes came from the cache


def _watch(tmp_path, spec):
    sc, path, rt = _setup(tmp_path)
    got = {"progress": [], "done": None, "error": None}
    ended = threading.Event()

    def done(table, line):
        got["done"] = (table, line)
        ended.set()

    def error(line):
        got["error"] = line
        ended.set()

    b = FirstUseBuild(rt, path, str(tmp_path), got["progress"].append, done, error, spec, idle=False)
    b.start()
    assert ended.wait(120.0), b.status
    b.join(10.0)
    return rt, got


def test_a_worker_process_reports_each_station_and_hands_over_the_cached_table(tmp_path):
    rt, got = _watch(tmp_path, TINY)
    assert got["error"] is None, got["error"]
    table, line = got["done"]
    assert "first-use table ready (2 stations, depth <= 2.5 mm" in line, line
    assert "nice +19" in got["progress"][0], got["progress"]
    assert [p.split(" (")[0] for p in got["progress"][1:]] == ["station 1/2", "station 2/2"], got["progress"]
    assert np.array_equal(table["correction"], load_first_use_table(rt, ArrayCache(str(tmp_path)),
                                                                     TINY)["correction"])


def test_a_failing_build_reports_its_error_and_hands_over_nothing(tmp_path):
    rt, got = _watch(tmp_path, FirstUseSpec(stations=2, h=0.2, depth_max=0.0025))   # h out of range
    assert got["done"] is None
    assert "first-use table build failed" in got["error"] and "ValueError" in got["error"], got["error"]
    assert load_first_use_table(rt, ArrayCache(str(tmp_path)), TINY) is None
