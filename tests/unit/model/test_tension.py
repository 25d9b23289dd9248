"""The sheet's tension model (flexsheet.model.tension): the Gent modulus and its small-strain limit, the
string formula for the stiffness and its inverse, saturation reported."""

import numpy as np
import pytest

from flexsheet.model.tension import (
    SheetMaterial,
    clamp_force,
    gent_modulus,
    stiffness,
    stretch_for_stiffness,
    tension,
)


def test_gent_modulus_and_small_strain_limit():
    E = gent_modulus(50.0)
    assert 2.3e6 < E < 2.6e6
    mat = SheetMaterial()
    eps = 1e-4   # neo-Hooke → Hooke: T ≈ E t ε at small strain
    assert tension(eps, mat) == pytest.approx(mat.young * mat.thickness * eps, rel=1e-3)
    assert clamp_force(eps, mat) == pytest.approx(mat.young * mat.thickness * mat.size * eps, rel=1e-3)


def test_stiffness_string_formula_and_inverse_roundtrip():
    mat = SheetMaterial()
    e = 0.05
    L = mat.size * 1.05
    assert stiffness(e, mat) == pytest.approx(tension(e, mat) * mat.contact_width * 4.0 / L)
    assert stiffness(e, mat, 0.05) > stiffness(e, mat)       # stiffer near a clamp
    for k in (10.0, 20.0, 35.0):
        r = stretch_for_stiffness(k, mat, 0.02)
        assert r.saturated == ""
        assert stiffness(r.stretch, mat, 0.02) == pytest.approx(k, rel=1e-8)


def test_inverse_reports_saturation():
    mat = SheetMaterial()
    hi = stretch_for_stiffness(1e4, mat)
    assert hi.saturated == "object_stiffer_than_sheet" and hi.force <= mat.max_force + 1e-6
    lo = stretch_for_stiffness(0.0, mat)
    assert lo.saturated == "object_softer_than_sheet" and lo.stretch == mat.min_stretch
    with pytest.raises(ValueError, match="k_target"):
        stretch_for_stiffness(float("nan"), mat)
    with pytest.raises(ValueError, match="young"):
        SheetMaterial(young=-1.0)


def test_force_inverse_meets_the_force_and_saturates_at_the_pull_limit():
    from flexsheet.model.tension import press_force, stretch_for_force

    mat = SheetMaterial(contact_width=0.023, contact_growth=2.7, stretching=1.7e4, strain_offset=0.01)
    for u, d, f in ((0.0, 0.005, 0.3), (0.04, 0.012, 1.6), (-0.06, 0.02, 4.0)):
        r = stretch_for_force(f, mat, u, d)
        assert not r.saturated and press_force(r.stretch, mat, u, d) == pytest.approx(f, rel=1e-8)
        assert r.force <= mat.max_force + 1e-9
    hi = stretch_for_force(50.0, mat, 0.0, 0.005)
    assert hi.saturated == "object_stiffer_than_sheet" and hi.force == pytest.approx(mat.max_force, rel=1e-6)
    lo = stretch_for_force(0.0, mat, 0.0, 0.005)
    assert lo.saturated == "object_softer_than_sheet" and lo.stretch == mat.min_stretch
    with pytest.raises(ValueError, match="depth"):
        stretch_for_force(1.0, mat, 0.0, 0.0)
    with pytest.raises(ValueError, match="force"):
        stretch_for_force(-1.0, mat, 0.0, 0.01)


def test_the_position_terms_scale_force_and_stiffness_where_the_finger_presses_and_bad_ones_are_named():
    from flexsheet.model.tension import position_factor, press_force

    rng = np.random.default_rng(5)
    pu, pv = float(rng.uniform(0.1, 0.5)), float(rng.uniform(-0.7, -0.2))
    band = SheetMaterial(contact_width=0.025, own_growth=200.0)
    m = SheetMaterial(contact_width=0.025, own_growth=200.0, position_u=pu, position_v=pv)
    u, v, d, s = 0.06, 0.03, 0.008, 0.03
    h = 1.0 + pu * (u / 0.12) ** 2 + pv * (v / 0.12) ** 2
    assert position_factor(m, u, v) == pytest.approx(h) and position_factor(band, u, v) == 1.0
    assert press_force(s, m, u, d, v) == pytest.approx(h * press_force(s, band, u, d), rel=1e-12)
    assert stiffness(s, m, u, d, v) == pytest.approx(h * stiffness(s, band, u, d), rel=1e-12)
    assert press_force(s, m, 0.0, d) == pytest.approx(press_force(s, band, 0.0, d), rel=1e-12)   # the centre
    for name, bad in (("position_u", float("nan")), ("position_v", -1.0), ("position_u", 6.0)):
        with pytest.raises(ValueError, match=name):
            SheetMaterial(**{name: bad})
