"""The one way the FEM node's model is built (flexsheet.fem.served): every object is a scene file whose
material and finger the model takes; the paper's cylinder on its own mesh with its snapshot table."""

import dataclasses

import numpy as np
import pytest

from flexsheet.fem.config import FemConfig
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.served import attach_table, build_model, uses_cylinder_mesh
from flexsheet.model.scenes import SCENES_DIR, load_scene, parse_scene

#: a coarse P1 mesh and no disk cache: seconds to precompute
COARSE = FemConfig(mesh_h=0.012, mesh_h_fine=0.006, refine_radius=0.012, order=1, cache_dir="")


def _cylinder(**changes):
    """launch/scenes/cylinder.yaml with ``changes`` merged into its top-level sections."""
    data = load_scene(SCENES_DIR / "cylinder.yaml").model_dump()
    for k, v in changes.items():
        data[k] = {**data[k], **v} if isinstance(v, dict) else v
    return parse_scene(data, "<cylinder, changed>")


def test_the_cylinder_takes_its_material_and_finger_from_the_scene_file():
    """Twice the scene's E, twice the force of the same push; the scene's finger radius is the model's."""
    cfg = dataclasses.replace(COARSE, model="linear")
    tip = np.array([-0.005, 0.0, 0.0])
    forces = []
    for sc in (_cylinder(), _cylinder(material={"E": 20000.0}), _cylinder(finger={"radius": 0.010})):
        m, line = build_model(sc, cfg)
        assert isinstance(m, RealtimeModel) and m.finger_radius == sc.finger.radius
        assert "scene 'cylinder'" in line and "the cylinder's mesh" in line, line
        t = attach_table(m, sc, cfg)
        assert t.where is None and m.snapshots is None and "linear model (model=linear)" in t.message
        forces.append(m.update(tip).force)
    assert forces[0] > 0.0 and forces[1] == pytest.approx(2.0 * forces[0], rel=1e-6)
    assert abs(forces[2] - forces[0]) > 0.05 * forces[0], forces     # the scene's finger is the one solved


def test_the_cylinder_scene_gets_its_shipped_table_and_a_missing_one_is_named():
    sc = load_scene(SCENES_DIR / "cylinder.yaml")
    m, _ = build_model(sc, COARSE)
    t = attach_table(m, sc, COARSE)
    assert t.kind == "snapshots" and t.where == "the shipped store (flexsheet/fem/data)" and not t.missing
    assert m.snapshots is not None and np.degrees(m.snapshots.angle_max) == pytest.approx(60.0)
    neo = _cylinder(material={"model": "neo_hookean", "Jm": None})
    m, _ = build_model(neo, COARSE)
    t = attach_table(m, neo, dataclasses.replace(COARSE, model="snapshots"))
    assert t.missing and t.where is None and m.snapshots is None
    assert ("--node-table --nu 0.45 --Jm inf" in t.message
            and t.what == "linear P1 cylinder model (no snapshot table stored)")


def test_only_the_paper_cylinder_as_shipped_uses_the_cylinder_mesh():
    assert uses_cylinder_mesh(load_scene(SCENES_DIR / "cylinder.yaml"))
    assert not uses_cylinder_mesh(_cylinder(object={"radius": 0.03}))
    assert not uses_cylinder_mesh(_cylinder(support={"kind": "half_space", "point": [-0.06, 0.0, 0.0],
                                                     "normal": [1.0, 0.0, 0.0], "tolerance": 0.0005}))
    assert not uses_cylinder_mesh(load_scene(SCENES_DIR / "sphere.yaml"))


def test_a_scene_without_a_stored_table_gets_its_first_use_table_and_a_full_table_wins(tmp_path):
    """The sticky sphere with a short stroke (tests/unit/conftest.py) has no stored path table: linear, named
    missing; with its first-use table cached (flexsheet/fem/first_use.py's key; a closed-form table) that
    table is attached and said to be the first use's; with a full path table under the full key too, the full
    one is attached."""
    from test_path_snapshots import _table

    from flexsheet.fem.cache import ArrayCache
    from flexsheet.fem.first_use import first_use_key
    from flexsheet.fem.path_snapshots import path_table_key
    from unit.conftest import _scene

    sc, cfg = _scene(), dataclasses.replace(COARSE, cache_dir=str(tmp_path))
    m, _ = build_model(sc, cfg)
    t = attach_table(m, sc, cfg)
    assert t.missing and t.kind == "path" and t.where is None and m.path_table is None
    assert "table_build=true" in t.message
    cache = ArrayCache(str(tmp_path))
    first = _table(m)
    cache.save("pathsnap", first_use_key(sc, m), first)
    m, _ = build_model(sc, cfg)
    t = attach_table(m, sc, cfg)
    assert t.where == "cache (built on first use)" and not t.missing, t
    assert "nonlinear path table loaded from cache (built on first use): 3 stations" in t.message, t.message
    assert m.path_table is not None and len(m.path_table.fractions) == 3
    full = dict(first, fractions=np.array([0.0, 0.4, 1.0]))
    cache.save("pathsnap", path_table_key(m.scene_key, m.cache_key), full)
    m, _ = build_model(sc, cfg)
    t = attach_table(m, sc, cfg)
    assert t.where == "cache" and np.allclose(m.path_table.fractions, [0.0, 0.4, 1.0]), t
