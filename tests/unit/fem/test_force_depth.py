"""The object's force-depth from the served FEM (flexsheet.fem.force_depth): physically right at small depth
(Hertz, where it applies), rising with depth, the same object the FEM node deforms."""

import numpy as np
import pytest

from flexsheet.fem.force_depth import SOLVED_FROM, build_force_depth, contact_fit, hertz_check
from flexsheet.fem.served import served_model
from flexsheet.model.scenes import load_scene


@pytest.mark.parametrize("name", ["cylinder", "sphere"])
def test_the_table_meets_hertz_at_small_depth_where_the_served_model_alone_does_not(name):
    sc = load_scene(f"launch/scenes/{name}.yaml")
    model, _ = served_model(sc)
    fd = build_force_depth(sc, model, n_points=3, depth_max=0.012)
    h = hertz_check(sc, fd)
    assert h is not None and fd.names[0] == "reference"
    # within 12 % of Hertz at 1-3 mm (contact radius <= r_f / 1.7): the FEM's amplitude at 2.5-5 mm
    assert all(0.95 < r < 1.12 for r in h["ratio"]), h["ratio"]
    # the served model alone interpolates linearly below its first solved depth: +50 % or more at 1 mm
    model.reset()
    raw = model.update(fd.points[0] - fd.normals[0] * 0.001).force
    assert raw / h["hertz_n"][0] > 1.5
    assert np.all(np.diff(fd.force, axis=1) >= 0.0) and fd.force[:, -1].min() > 0.5


def test_the_organ_table_is_stiffer_over_its_tumour_and_hertz_is_not_claimed_there():
    sc = load_scene("launch/scenes/organ.yaml")
    fd = build_force_depth(sc, n_points=9)
    assert hertz_check(sc, fd) is None
    f10 = np.array([fd.force_at(p, 0.01) for p in fd.points])
    inc = np.asarray(sc.inclusions[0].center)
    near = int(np.argmin(np.linalg.norm(fd.points - inc, axis=1)))
    assert f10[near] > 1.1 * np.median(f10), (near, f10.round(3).tolist())


def test_contact_fit_replaces_only_the_unsolved_shallow_part():
    d = np.arange(0.0, 0.0101, 0.0005)
    f = 2000.0 * d ** 1.5
    f[(d > 0) & (d < SOLVED_FROM)] = (2000.0 * SOLVED_FROM ** 1.5 * d[(d > 0) & (d < SOLVED_FROM)]
                                      / SOLVED_FROM)
    fit, c = contact_fit(d, f)
    assert c == pytest.approx(2000.0, rel=1e-9) and np.allclose(fit, 2000.0 * d ** 1.5)
    with pytest.raises(ValueError, match="depth"):
        contact_fit(np.array([0.0, 0.0005]), np.array([0.0, 0.01]))
