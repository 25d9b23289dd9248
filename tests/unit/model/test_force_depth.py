"""The object's force-depth table and its mapping (flexsheet.model.force_depth): look-up along the stroke, the
contrast gain, one scale per scene, and the errors."""

import math

import numpy as np
import pytest

from flexsheet.model.force_depth import ForceDepth, scene_scale

D = np.linspace(0.0, 0.02, 41)


def _table(c=(1000.0, 1000.0, 2000.0)) -> ForceDepth:
    """Three points 10 mm apart along +z with F = c·d^1.5 each (the middle one a stiff 'inclusion' when c
    differs)."""
    P = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.01], [0.0, 0.0, 0.02]])
    F = np.array([ci * D ** 1.5 for ci in c])
    return ForceDepth(P, np.tile([1.0, 0.0, 0.0], (3, 1)), ("reference", "a", "b"), D, F, "key")


def test_lookup_interpolates_along_the_stroke_and_in_depth_and_extrapolates_past_the_deepest():
    t = _table((1000.0, 2000.0, 2000.0))
    d = 0.0075
    assert t.force_at([0.0, 0.0, 0.0], d) == pytest.approx(1000 * d ** 1.5, rel=0.01)
    assert t.force_at([0.0, 0.0, 0.005], d) == pytest.approx(1500 * d ** 1.5, rel=0.01)   # half-way
    # 3 mm off the stroke
    assert t.force_at([0.003, 0.0, 0.015], d) == pytest.approx(2000 * d ** 1.5, rel=0.01)
    slope = 1000 * (D[-1] ** 1.5 - D[-2] ** 1.5) / (D[-1] - D[-2])
    assert t.force_at([0.0, 0.0, 0.0], 0.03) == pytest.approx(1000 * 0.02 ** 1.5 + slope * 0.01, rel=1e-9)
    assert t.force_at([0.0, 0.0, 0.0], 0.0) == 0.0


def test_mapping_keeps_ratios_at_gain_one_and_raises_contrast_keeping_order_above():
    t = _table()
    q_body, q_inc = [0.0, 0.0, 0.0], [0.0, 0.0, 0.02]
    d = 0.01
    fb, kb = t.mapped(q_body, d, 0.5)
    fi, _ = t.mapped(q_inc, d, 0.5)
    assert fb == pytest.approx(0.5 * 1000 * d ** 1.5, rel=1e-6) and fi / fb == pytest.approx(2.0, rel=1e-6)
    assert kb == pytest.approx(0.5 * 1.5 * 1000 * d ** 0.5, rel=1e-3)      # dF/dd of c·d^1.5
    gi, _ = t.mapped(q_inc, d, 0.5, gain=2.5)
    gb, _ = t.mapped(q_body, d, 0.5, gain=2.5)
    # body = median
    assert gi / gb == pytest.approx(2.0 ** 2.5, rel=1e-6) and gb == pytest.approx(fb, rel=1e-6)


def test_scene_scale_is_the_geometric_centre_of_the_range_that_fits_and_says_when_none_does():
    t = _table()
    floor = lambda d: 10.0 * d             # noqa: E731 - the sheet's least and largest force, N
    ceil = lambda d: 400.0 * d             # noqa: E731
    s = scene_scale(t, floor, ceil, 0.002, 0.02)
    # request c·d^1.5 / sheet k·d = (c/k)·√d: the softest sample at 2 mm, the stiffest at 20 mm
    lo, hi = 10.0 / (1000 * math.sqrt(0.002)), 400.0 / (2000 * math.sqrt(0.02))
    assert s.low == pytest.approx(lo, rel=1e-9) and s.high == pytest.approx(hi, rel=1e-9)
    assert s.fits and s.saturated == 0.0 and s.scale == pytest.approx(math.sqrt(lo * hi), rel=1e-9)
    narrow = scene_scale(t, floor, lambda d: 12.0 * d, 0.002, 0.02)
    assert not narrow.fits and 0.0 < narrow.saturated < 1.0


@pytest.mark.parametrize("field,kw,match", [
    ("points", {"points": np.zeros((1, 3))}, "points"),
    ("depths", {"depths": D[::-1]}, "depths"),
    ("force", {"force": -np.ones((3, len(D)))}, "force"),
    ("names", {"names": ("reference",)}, "names"),
])
def test_a_bad_table_is_refused_naming_the_field(field, kw, match):
    t = _table()
    args = {"points": t.points, "normals": t.normals, "names": t.names, "depths": t.depths, "force": t.force}
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        ForceDepth(**args)


def test_bad_lookups_and_mappings_are_refused():
    t = _table()
    with pytest.raises(ValueError, match="depth"):
        t.force_at([0, 0, 0], -0.001)
    with pytest.raises(ValueError, match="contact point"):
        t.force_at([0, 0, float("nan")], 0.001)
    with pytest.raises(ValueError, match="scale"):
        t.mapped([0, 0, 0], 0.001, 0.0)
    with pytest.raises(ValueError, match="contrast_gain"):
        t.mapped([0, 0, 0], 0.001, 1.0, gain=float("inf"))
    assert (ForceDepth.from_json(t.to_json()).force_at([0, 0, 0.01], 0.005)
            == pytest.approx(t.force_at([0, 0, 0.01], 0.005)))
    with pytest.raises(ValueError, match="malformed"):
        ForceDepth.from_json({"points": []})
