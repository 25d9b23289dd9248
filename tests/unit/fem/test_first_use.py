"""What a scene's first-use table holds (flexsheet/fem/first_use.py): pushes to the scene's use.max_depth in
the full table's 2.5 mm steps (so its depths are the full table's first ones), on the spec's mesh; its key is
the full table's key and the spec, never the full table's own."""

import numpy as np

from flexsheet.fem.first_use import FIRST_USE, FirstUseSpec, first_use_key, first_use_settings
from flexsheet.fem.path_snapshots import path_table_key
from flexsheet.fem.reference.scene_reference import FULL
from flexsheet.model.scene_draw import draw_scene
from flexsheet.model.scenes import parse_scene
from unit.conftest import _scene


class _Model:
    cache_key = "rt-key"


def test_a_drawn_object_is_pushed_to_its_use_depth_in_the_full_tables_steps():
    data = _scene().model_dump()
    data["use"] = dict(draw_scene(0)[0]["use"])          # a drawn object's: 20 mm
    sc = parse_scene(data, "<sphere used as a drawn object>")
    st = first_use_settings(sc)
    assert sc.use.max_depth == 0.02
    assert np.allclose(st["depths"], np.arange(1, 9) * 0.0025) and st["path_depth"] == 0.02
    assert np.array_equal(st["depths"], FULL["depths"][:8])           # the full table's first depths
    assert (st["h"], st["refine_radius"], FIRST_USE.h_fine, FIRST_USE.stations) == (0.012, 0.015, 0.008, 3)
    assert first_use_settings(sc, FirstUseSpec(depth_max=0.011))["depths"][-1] == 0.0125   # rounded up


def test_its_key_is_its_own_and_follows_the_spec():
    sc, rt = _scene(), _Model()
    k = first_use_key(sc, rt)
    assert k != path_table_key(sc.key(), rt.cache_key)
    assert k == first_use_key(sc, rt, FIRST_USE)
    assert k != first_use_key(sc, rt, FirstUseSpec(stations=5))
