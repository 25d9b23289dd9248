"""The material (flexsheet/fem/material.py): a bad Gent limit is refused, the key names it."""

import math

import pytest

from flexsheet.fem.material import Material


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, True])
def test_material_rejects_a_bad_gent_limit(bad):
    with pytest.raises(ValueError, match="Jm"):
        Material(Jm=bad)
    assert Material().key() == "E=10000,nu=0.45" and Material(Jm=97.2).key() == "E=10000,nu=0.45,Jm=97.2"
